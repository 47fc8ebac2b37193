"""The learning stages (paper Sec. III): features and their layout, dataset files, the MANN,
the physics-informed loss and its kinematics, training, and the trained network's diagnostics."""

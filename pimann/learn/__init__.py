"""The learning stages (paper Sec. III-A and III-B): features and their layout, dataset files,
the MANN, the physics-informed loss and its kinematics, and training."""

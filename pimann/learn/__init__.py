"""The learning stages (paper Sec. III-A and III-B): features and their layout, dataset files,
the MANN, the physics-informed loss and its kinematics, training, and the trained network's
diagnostics.

A package's summary only (hence so short): its modules hold the code."""

"""Trajectory control in MuJoCo (paper Sec. II-C, offline controller; SPEC 9).

model: the MuJoCo ergoCub from the `_minContacts` URDF, foot forces and measured ZMP.
footsteps: footsteps and timing from a generated trajectory's contacts (0.33x speed, 0.4x steps).
dcm: offline DCM/ZMP adjustment over the whole horizon (casadi).
wbc: whole-body QP IK (pink + daqp) and the ZMP-CoM feedback law.
run: the closed loop, `simulate_trajectory(trajectory, params) -> SimulationResult`.
synthetic: a kinematic stepping trajectory for tests and benchmarks.
"""

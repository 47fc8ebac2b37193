"""Trajectory control in MuJoCo (paper Sec. II-C, both controllers).

model: the MuJoCo ergoCub from the `_minContacts` URDF, foot forces and measured ZMP.
footsteps: footsteps and timing from a generated trajectory's contacts (0.33x speed, 0.4x steps).
dcm: offline DCM/ZMP adjustment over the whole horizon (casadi).
com_reference: the generated CoM mapped onto the footstep plan, which the DCM plan stays near.
centroidal_mpc: the online controller's centroidal MPC with step adjustment (casadi).
online: the MPC replanned in the closed loop: CoM, ZMP and adjusted footsteps for the IK.
wbc: whole-body QP IK (pink + daqp) and the ZMP-CoM feedback law.
closed_loop: the closed loop, `simulate_trajectory(trajectory, params, controller=...)`.
synthetic: a kinematic stepping trajectory for tests and benchmarks.
simulation_files: a run written to (and read from) HDF5, the ZMP-outside-the-support figure.
run_list: the simulate stage's runs and push studies, one result file each, and their summary.
video: offscreen MuJoCo rendering of a run (stick-figure fallback without OpenGL).
"""

import os

# MuJoCo picks its OpenGL backend when first imported: headless, EGL is the one that works
# here (OSMesa does not). A display or an explicit MUJOCO_GL keeps the user's choice.
if "DISPLAY" not in os.environ:
    os.environ.setdefault("MUJOCO_GL", "egl")

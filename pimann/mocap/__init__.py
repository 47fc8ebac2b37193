"""Human motion capture: readers (XSens YARP log, MVNX, BVH), resampling, mirroring."""

from pimann.mocap.human_motion import HumanMotion
from pimann.mocap.io import mocap_info, read_mocap
from pimann.mocap.mirror import mirror_human, mirror_trajectory
from pimann.mocap.resample import resample

__all__ = [
    "HumanMotion",
    "mirror_human",
    "mirror_trajectory",
    "mocap_info",
    "read_mocap",
    "resample",
]

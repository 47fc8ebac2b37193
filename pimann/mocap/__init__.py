"""Human motion capture: readers (XSens YARP log, MVNX, BVH), resampling, mirroring."""

from pimann.mocap.human_motion import HumanMotion

__all__ = ["HumanMotion"]

"""Autoregressive generation (paper Sec. III-C): the rollout, the steering law, leg odometry,
command scripts and the rollout stage."""

"""Autoregressive generation (paper Sec. IV): the rollout, the steering law, leg odometry,
command scripts, the rollout stage and its file layout, and the rollout diagnostics."""

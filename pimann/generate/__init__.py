"""Autoregressive generation (paper Sec. III-C): the rollout, the steering law, leg odometry,
command scripts, the rollout stage and its file layout, and the rollout diagnostics.

A package's summary only (hence so short): its modules hold the code."""

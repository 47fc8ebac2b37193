"""What every stage shares: parameters, paths, errors, atomic writes, progress and logs, the
stage entry and its data check, the robot, the trajectory file, the rollout files' layout,
rotations and foot contacts.

Imports nothing above it (tests/test_import_order.py)."""

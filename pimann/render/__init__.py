"""Pictures of trajectories: stick figures of the robot (and of the person beside it), drawn
to .png strips, .gif and .mp4. Sits just above mocap, which the person's drawing reads."""

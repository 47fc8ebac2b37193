"""Window forcing on a real clip: a network that returns the data's outputs walks as the clip
in both modes; one whose legs stand still does not, whatever the windows."""

from __future__ import annotations

import numpy as np
import torch

from diagnostics.window_forcing import forced_rollouts, gait_measures
from pimann.core.params import load_params
from pimann.learn.feature_layout import Normalisation, window_layout
from pimann.learn.features import clip_features

PARAMS = load_params()


def _run(clip, frozen_legs: bool):
    layout = window_layout(PARAMS.features, 50.0, "full")
    _, y, _ = clip_features(clip, layout)
    n_in, n_out = layout.input_dim, layout.output_dim
    identity = Normalisation(np.zeros(n_in), np.ones(n_in), np.zeros(n_out), np.ones(n_out))
    joints = layout.y_slices["joints"]
    calls = [0]

    def oracle(x):
        k = calls[0]
        calls[0] += 1
        out = np.repeat(y[k : k + 1], len(x), axis=0)
        if frozen_legs:  # the first output's joints, still
            out[:, joints] = y[0, joints]
            out[:, layout.y_slices["joint_velocities"]] = 0.0
        return out

    runs = forced_rollouts(
        torch.nn.Linear(n_in, n_out), layout, identity, clip, PARAMS, 3.0, network=oracle
    )
    return {mode: gait_measures(runs[mode], runs["data"]) for mode in ("free", "windows")}, runs


def test_the_data_walks_as_the_clip_in_both_modes(real_walks):
    for name in ("walk", "walk_back"):
        measures, runs = _run(real_walks[name], frozen_legs=False)
        data = gait_measures(runs["data"], runs["data"])
        assert abs(data["speed_ratio"] - 1.0) < 1e-12 and data["leg_rmse"] == 0.0
        for mode in ("free", "windows"):
            assert measures[mode]["leg_rmse"] < 1e-9, (name, mode)
            assert abs(measures[mode]["speed_ratio"] - 1.0) < 0.1, (name, mode, measures)
            assert measures[mode]["touchdowns"] > 3  # it steps


def test_frozen_legs_do_not_walk_even_under_the_data_windows(real_walks):
    measures, _ = _run(real_walks["walk"], frozen_legs=True)
    for mode in ("free", "windows"):
        assert abs(measures[mode]["speed_ratio"]) < 0.1, (mode, measures)
        assert measures[mode]["leg_rmse"] > 0.05

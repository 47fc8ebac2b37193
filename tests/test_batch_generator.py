"""Batched generation (pimann.generate.batch_generator): a row of a batch is the same rollout alone.

Float64 models (the analytic gait of test_generate and a tiny trained MANN), so the only
difference a batch could make is rounding; rows with different scripts (stand segments
between motions: stops and restarts), lengths and steering share one batch.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import torch
from builders import IDENTITY, LAYOUT, GaitModel

from pimann.core.contacts import FEET
from pimann.core.params import ModelParams, MotionSegment, StandSegment
from pimann.generate.batch_generator import BatchGenerator
from pimann.generate.leg_odometry import SoleFrames
from pimann.generate.rollout_batch import RolloutSpec, generate_batch, generate_rollout
from pimann.generate.rollout_network import NumpyMANN
from pimann.learn.feature_layout import Normalisation
from pimann.learn.features import clip_features
from pimann.learn.mann import MANN
from pimann.learn.standing import StandingPose

M, S = MotionSegment, StandSegment
SCRIPTS = [
    [S(0.3, True), M(1.5, 0.5, 0.0, 0.2), S(1.0, True), M(1.0, -0.3, 0.1, 0.0)],  # stop, restart
    [M(2.5, 0.6, 0.0, 0.0)],  # ends walking
    [M(0.8, 0.3, 0.2, -0.3), S(1.5, True)],  # ends standing
    [S(0.5, True), M(1.2, 0.4, 0.0, 0.0)],
]


def test_sole_frames_match_pinocchio(robot, rng):
    joints = rng.uniform(robot.joint_lower, robot.joint_upper, size=(6, 26))
    positions, rotations = SoleFrames(robot)(joints)
    for row, values in enumerate(joints):
        q = robot.configuration(np.zeros(3), [0.0, 0.0, 0.0, 1.0], values)
        for column, frame in enumerate(FEET):
            placement = robot.frame_placement(q, frame)
            np.testing.assert_allclose(positions[row, column], placement.translation, atol=1e-12)
            np.testing.assert_allclose(rotations[row, column], placement.rotation, atol=1e-12)


def assert_same_rollout(alone, row, tolerance: float = 1e-9, frames: int | None = None) -> None:
    """Equal over the first `frames` frames (all by default)."""
    a, b = alone.trajectory, row.trajectory
    assert len(a) == len(b) and a.attrs == b.attrs and a.source == b.source
    cut = slice(0, len(a) if frames is None else frames)
    for name in ("base_position", "base_quaternion_xyzw", "joint_positions", "joint_velocities"):
        # relative beyond 1: a fitted network's joint velocities reach tens of rad/s
        np.testing.assert_allclose(
            getattr(b, name)[cut], getattr(a, name)[cut], rtol=tolerance, atol=tolerance
        )
    np.testing.assert_array_equal(b.contacts[cut], a.contacts[cut])
    np.testing.assert_allclose(row.goals[cut], alone.goals[cut], rtol=0, atol=tolerance)
    np.testing.assert_array_equal(row.stopped[cut], alone.stopped[cut])
    np.testing.assert_array_equal(row.support[cut], alone.support[cut])


def frames_in_range(rollout, joint_speed: float) -> int:
    """Frames before the first whose joint speed passes `joint_speed` (rad/s)."""
    fast = np.flatnonzero(np.abs(rollout.trajectory.joint_velocities).max(axis=1) > joint_speed)
    return int(fast[0]) if len(fast) else len(rollout.trajectory)


def batch_against_alone(
    model,
    stats,
    params,
    robot,
    scripts=SCRIPTS,
    tolerance: float = 1e-9,
    joint_speed: float | None = None,
    **changes,
) -> list:
    """Every script with and without steering in one batch; each row against its rollout,
    up to the first frame whose joint speed passes `joint_speed` where one is given."""
    rollout_params = dataclasses.replace(params.rollout, **changes)
    pairs = [(script, steering) for steering in (False, True) for script in scripts]
    specs = [RolloutSpec(s, st, f"row{i}", {"row": i}) for i, (s, st) in enumerate(pairs)]
    rows = generate_batch(
        model, LAYOUT, stats, specs, rollout_params, robot, contact_params=params.contacts
    )
    for spec, row in zip(specs, rows, strict=True):
        alone = generate_rollout(
            model,
            LAYOUT,
            stats,
            spec.script,
            rollout_params,
            spec.steering,
            robot,
            contact_params=params.contacts,
            source=spec.source,
            attrs=spec.attrs,
        )
        frames = None if joint_speed is None else frames_in_range(alone, joint_speed)
        assert frames is None or frames >= 35, f"{spec.source} leaves the range at {frames}"
        assert_same_rollout(alone, row, tolerance, frames)
    return rows


@pytest.fixture(scope="module")
def params():
    from pimann.core.params import load_params

    return load_params()


def test_gait_rows_equal_their_rollouts_alone(robot, params):
    model = GaitModel(robot, bias=(0.02, 0.05)).double()
    rows = batch_against_alone(model, IDENTITY, params, robot)
    assert [len(r.trajectory) for r in rows[:4]] == [191, 126, 116, 86]
    stops = np.diff(rows[0].stopped.astype(int))
    assert np.flatnonzero(stops)[0] == 15  # walks from frame 16
    assert (stops == 1).sum() == 1 and (stops == -1).sum() == 2  # stopped, then restarted
    for steered in (rows[0], rows[4]):
        assert not steered.stopped[-1]  # walking again at the end
    assert rows[2].stopped[-1] and rows[6].stopped[-1]
    moved = [np.abs(r.trajectory.base_position[-1, :2]).max() for r in rows]
    assert min(moved) > 0.2  # every row walked


@pytest.fixture(scope="module")
def trained(robot, params) -> tuple[MANN, Normalisation]:
    """A float64 MANN trained on the gait's forward walk with a stop, and its statistics."""
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    walk = M(3.0, 0.5, 0.0, 0.0)
    data = generate_rollout(
        GaitModel(robot),
        LAYOUT,
        IDENTITY,
        [walk, S(1.5, True), walk],
        params.rollout,
        True,
        robot,
        contact_params=params.contacts,
    ).trajectory
    x, y, _ = clip_features(data, LAYOUT)
    stats = Normalisation.fit(x, y)
    xn = torch.tensor(stats.normalise_x(x), dtype=torch.float64)
    yn = torch.tensor(stats.normalise_y(y), dtype=torch.float64)
    torch.manual_seed(3)
    model = MANN(
        LAYOUT.input_dim, LAYOUT.output_dim, ModelParams(2, 8, 2, 32, 2, 0.0, "elu"), seeds=[0]
    ).double()
    optimiser = torch.optim.Adam(model.parameters(), lr=3e-3)
    for _ in range(800):
        optimiser.zero_grad()
        loss = torch.mean((model(xn) - yn) ** 2)
        loss.backward()
        optimiser.step()
    torch.set_num_threads(threads)
    assert loss.item() < 0.01
    return model.eval(), stats


def test_trained_mann_rows_equal_their_rollouts_alone(robot, params, trained):
    """Alone, the network runs in numpy (`NumpyMANN`), in a batch in torch: rows equal their
    rollouts alone to rounding (contacts, stops and support feet identical). A fitted network's
    rollout is chaotic (which foot lifts first at a start is a near tie), and BLAS rounding
    that depends on the batch size (1e-16 in float64, 1e-7 in float32) grows fast once the
    rollout leaves the data: the network, fitted to one 7.5 s clip, steered into a stand it
    never saw, passes 50 rad/s within 0.8-1.2 s and 1e5 rad/s soon after, where 1e-16 has
    grown to metres. So float64, short walks, and the comparison up to the first frame past
    50 rad/s (at least 35 frames of each row, 0.7 s; where an unsteered row leaves the range
    depends on the CPU's BLAS kernels, which fit the network a little differently).
    float32 equality is per call (`test_numpy_mann_equals_forward`) and the closed-form gait
    above checks long rollouts to 1e-9."""
    torch.set_num_threads(1)
    model, stats = trained
    model = MANN.member(model, 0).to(torch.float64).eval()
    scripts = [
        [S(0.3, True), M(0.8, 0.5, 0.0, 0.0), S(0.6, True)],
        [M(0.9, 0.5, 0.0, 0.0)],
        [M(0.8, 0.5, 0.0, 0.0), S(0.6, True)],
        [S(0.5, True), M(0.7, 0.4, 0.0, 0.0)],
    ]
    rows = batch_against_alone(model, stats, params, robot, scripts, 1e-9, joint_speed=50.0)
    changes = np.flatnonzero(np.diff(rows[0].stopped.astype(int)))
    assert list(changes) == [15, 55]  # walks at 16, stops during the 'stand'


@pytest.mark.parametrize(("dtype", "tolerance"), [(torch.float64, 1e-13), (torch.float32, 1e-6)])
def test_numpy_mann_equals_forward(params, dtype, tolerance):
    """The full-size network of params.yaml, one sample at a time and a batch."""
    model = MANN(LAYOUT.input_dim, LAYOUT.output_dim, params.model, seeds=[7]).to(dtype).eval()
    x = torch.randn(6, LAYOUT.input_dim, dtype=dtype, generator=torch.Generator().manual_seed(0))
    with torch.inference_mode():
        expected = model(x).numpy()
    network = NumpyMANN(model)
    for row in range(len(x)):
        y = network(x[row : row + 1].numpy())
        assert y.dtype == expected.dtype
        np.testing.assert_allclose(y, expected[row : row + 1], rtol=0, atol=tolerance)
    np.testing.assert_allclose(network(x.numpy()), expected, rtol=0, atol=tolerance)
    assert np.abs(expected).max() > 0.05  # outputs well above the tolerance


def test_a_cpu_model_runs_its_network_in_numpy(robot, params, trained):
    model, stats = trained
    generators = [
        BatchGenerator(
            candidate,
            LAYOUT,
            stats,
            params.rollout,
            np.ones(rows, bool),
            robot,
            params.contacts,
            StandingPose.nominal(),
        )
        for candidate, rows in ((model, 1), (model, 2), (_two_member(model), 2))
    ]
    assert isinstance(generators[0].network.numpy, NumpyMANN)  # alone
    assert isinstance(generators[1].network.numpy, NumpyMANN)  # a batch
    assert generators[2].network.numpy is None  # an ensemble keeps torch


def _two_member(model: MANN) -> MANN:
    return MANN(model.input_dim, model.output_dim, model.params, ensemble=2, seeds=[0, 1])

"""Training features (paper Sec. III-A, Eqs. nn_input and nn_output) and the leak-free split.

Step i of a clip gives one sample, as the authors' code builds it. The input x_i holds the base
linear and angular velocities at the input window's offsets around frame i, each rotated into
the base frame at i, then s_{i-1}, sdot_{i-1}, p_{i-1}, psi_{i-1}; the output y_i holds the
velocities at the output window's offsets from frame i + 1, rotated into the base frame at
i + 1, then s_i, sdot_i, p_i, psi_i (with `features.gait_phase`, beyond the paper, the gait
phase's cos and sin at i - 1 and i after them: pimann.learn.gait_phase). So y_i's window is
the next input's window at the output offsets (no output column copies an input column) and
its sample at offset 0 is the base motion from frame i to i + 1: the network generates the
base motion. Velocities are first differences
at the data rate (`first_differences`), so s_i = s_{i-1} + dt sdot_i holds in every pair. Both
windows come from params as seconds (the authors' and the paper's differ only there); psi are
Tait-Bryan angles in pinocchio's convention (R = Rz(yaw) Ry(pitch) Rx(roll)), yaw unwrapped
along a clip. Steps whose windows leave the clip are dropped.

The `ground_projected` variant (the ADHERENT baseline) replaces the base orientation by its
yaw alone (roll and pitch 0) before anything is computed; the base position, z included, is
kept, so the layout is the same as `full` and the rollout can reuse it. Its base velocities
are those of that projected frame (angular velocity about z only).

The split is by source clip: a clip and its mirror (same `source` attribute) land on the same
side, so no motion is seen in training and tested mirrored. Z-score statistics come from the
training samples only.

The dataset they make is written and read by pimann.learn.dataset.
"""

from __future__ import annotations

import logging
from collections.abc import Iterable, Sequence

import numpy as np
from scipy import ndimage
from scipy.spatial.transform import Rotation

from pimann.core.errors import PimannError
from pimann.core.params import FeaturesParams
from pimann.core.rotations import matrix_to_rpy, yaw_only
from pimann.core.trajectory import Trajectory
from pimann.learn.dataset import FeatureDataset
from pimann.learn.feature_layout import FeatureLayout, Normalisation, window_layout
from pimann.learn.gait_phase import gait_phase, phase_vector
from pimann.learn.motion_classes import CLASSES, class_counts, majority_class, spread_pick
from pimann.learn.standing import data_standing

log = logging.getLogger(__name__)


def first_differences(
    trajectory: Trajectory, projected: bool = False
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(rotations (T,3,3), linear (T,3), angular (T,3), joint velocities (T,nj)) of a clip.

    Velocities are first differences ending at each frame, as the authors' features: v_t =
    (p_t - p_{t-1}) / dt, omega_t = log(R_t R_{t-1}^T) / dt (world frame), sdot_t = (s_t -
    s_{t-1}) / dt, so that s_t = s_{t-1} + dt sdot_t and R_t = R_{t-1} exp(R_t^T omega_t dt)
    hold exactly: what the rollout integrates (pimann.generate.batch_generator). Frame 0 has no
    difference: NaN. `projected`: the base orientation kept to its yaw (the baseline's frame).
    """
    dt = 1.0 / trajectory.rate_hz
    rotations = Rotation.from_quat(trajectory.base_quaternion_xyzw).as_matrix()
    if projected:
        rotations = yaw_only(rotations)
    position = np.asarray(trajectory.base_position, dtype=float)
    joints = np.asarray(trajectory.joint_positions, dtype=float)
    linear = np.full(position.shape, np.nan)
    angular = np.full(position.shape, np.nan)
    joint_velocities = np.full(joints.shape, np.nan)
    if len(position) > 1:
        linear[1:] = np.diff(position, axis=0) / dt
        rot = Rotation.from_matrix(rotations)
        angular[1:] = (rot[1:] * rot[:-1].inv()).as_rotvec() / dt
        joint_velocities[1:] = np.diff(joints, axis=0) / dt
    return rotations, linear, angular, joint_velocities


def clip_phase(trajectory: Trajectory, layout: FeatureLayout) -> np.ndarray | None:
    """(T, 2) the gait phase's (cos, sin) from the clip's contacts (pimann.learn.gait_phase),
    or None when the layout has none."""
    if not layout.gait_phase:
        return None
    if trajectory.contacts is None:
        raise PimannError(trajectory.source, "features.gait_phase needs the clip's contacts")
    phase = gait_phase(trajectory.contacts, layout.rate_hz, layout.gait_phase_step_s)
    return phase_vector(phase)


def clip_features(
    trajectory: Trajectory, layout: FeatureLayout
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(X (N, in), Y (N, out), steps (N,)) of one clip, unnormalised, physical units.

    x_i: the input window of frame i in the base frame at i, then the state at i - 1; y_i: the
    output window of frame i + 1 in the base frame at i + 1, then the state at i (the authors'
    compute_X and compute_Y). y_i's window is x_{i+1}'s at the output offsets: the network
    predicts the next frame's base velocity and the window one frame ahead.
    """
    n = len(trajectory)
    none = np.empty((0, layout.input_dim)), np.empty((0, layout.output_dim)), np.empty(0, int)
    if n < 3:
        return none
    rotations, linear, angular, joint_velocities = first_differences(
        trajectory, layout.variant == "ground_projected"
    )
    position = trajectory.base_position
    joints = trajectory.joint_positions
    rpy = matrix_to_rpy(rotations)

    # every velocity used is a difference (index >= 1), sdot_{i-1} included
    first = max(2, 1 - min(layout.input_offsets))
    last = n - 1 - max(max(layout.input_offsets), 1 + max(layout.output_offsets))
    steps = np.arange(first, last + 1)
    if len(steps) == 0:
        return none

    def window(
        velocity: np.ndarray, centre: np.ndarray, window_offsets: tuple[int, ...]
    ) -> np.ndarray:
        """(N, 3 k) velocities at centre + offsets, written in the base frame at each centre."""
        at = velocity[centre[:, None] + np.asarray(window_offsets)[None, :]]  # (N, k, 3)
        to_base = rotations[centre].transpose(0, 2, 1)  # base <- world at the centre
        return np.einsum("nij,nkj->nki", to_base, at).reshape(len(centre), -1)

    phase = clip_phase(trajectory, layout)

    def state(at: np.ndarray) -> list[np.ndarray]:
        parts = [joints[at], joint_velocities[at], *layout.pose(position[at], rpy[at])]
        return parts if phase is None else [*parts, phase[at]]

    inputs, outputs = layout.input_offsets, layout.output_offsets
    x = np.concatenate(
        [window(linear, steps, inputs), window(angular, steps, inputs)] + state(steps - 1),
        axis=1,
    )
    ahead = steps + 1
    y = np.concatenate(
        [window(linear, ahead, outputs), window(angular, ahead, outputs)] + state(steps),
        axis=1,
    )
    return x, y, steps


REVERSED_SUFFIX = "~reversed"  # a time-reversed clip's name: its original's and this


def time_reversed(trajectory: Trajectory) -> Trajectory:
    """The clip played backward: every frame in reverse order on the same clock, contacts
    reversed (touchdowns become lift-offs), the source kept (the split keeps it beside its
    original). Joint velocities are not carried: the features take differences."""
    return Trajectory(
        time=np.asarray(trajectory.time, dtype=float),
        base_position=np.ascontiguousarray(trajectory.base_position[::-1]),
        base_quaternion_xyzw=np.ascontiguousarray(trajectory.base_quaternion_xyzw[::-1]),
        joint_positions=np.ascontiguousarray(trajectory.joint_positions[::-1]),
        source=trajectory.source,
        rate_hz=trajectory.rate_hz,
        contacts=None if trajectory.contacts is None else trajectory.contacts[::-1].copy(),
        attrs={**(trajectory.attrs or {}), "time_reversed": True},
    )


def with_time_reversed(
    clips: Sequence[tuple[str, Trajectory]], classes: Sequence[str], test_sources: set[str]
) -> list[tuple[str, Trajectory]]:
    """The clips, then each training clip whose class (`majority_class`) is in `classes` played
    backward (`time_reversed`) as `<name>~reversed`; test clips are never reversed."""
    if not classes:
        return list(clips)
    added = [
        (f"{name}{REVERSED_SUFFIX}", time_reversed(t))
        for name, t in clips
        if t.source not in test_sources and majority_class(class_counts(t)) in classes
    ]
    log.info("time-reversed %d training clips of classes %s", len(added), list(classes))
    return [*clips, *added]


def settled_contacts(contacts: np.ndarray, margin: int) -> np.ndarray:
    """(T, 2) contact flags kept only `margin` frames or more away from a switch of that foot.

    The clip's ends are not switches. Erosion by a (2 margin + 1)-frame window.
    """
    contacts = np.asarray(contacts, bool)
    if margin <= 0:
        return contacts.copy()
    structure = np.ones((2 * margin + 1, 1), bool)
    return ndimage.binary_erosion(contacts, structure, border_value=1)


PURE_SHARE = 0.75  # of a source's frames in its class: held out before the others


def split_sources(clips: Iterable[Trajectory], test_fraction: float, seed: int) -> set[str]:
    """The source clips held out for testing, stratified by motion class so that every class
    is tested on takes the model never saw: a class of 4 or more sources holds out 2 (of 2-3:
    1), of different styles where the labels name them (attrs["style"]); a seeded shuffle of
    the sorted unique names orders each class's and fills the rest of `test_fraction`.

    A source's class: pimann.learn.motion_classes.majority_class of its clips' frames pooled.
    """
    counts: dict[str, np.ndarray] = {}
    styles: dict[str, str | None] = {}
    for trajectory in clips:
        source = trajectory.source
        counts[source] = counts.get(source, 0) + class_counts(trajectory)
        styles.setdefault(source, str(trajectory.attrs.get("style") or "") or None)
    unique = sorted(counts)
    if not 0.0 < test_fraction < 1.0:
        raise PimannError(None, f"features.test_fraction must be in (0, 1), not {test_fraction}")
    if len(unique) < 2:
        raise PimannError(None, f"need at least 2 source clips to split, got {len(unique)}")
    n_test = min(len(unique) - 1, max(1, int(round(test_fraction * len(unique)))))
    order = [unique[k] for k in np.random.default_rng(seed).permutation(len(unique))]
    classes = {source: majority_class(counts[source]) for source in unique}
    test: list[str] = []
    for name in sorted(set(classes.values()), key=CLASSES.index):
        # sources that walk mostly in their class first (a crab walk is forward by majority,
        # but tells little about forward walking), in the shuffle's order
        code = CLASSES.index(name)
        members = sorted(
            (source for source in order if classes[source] == name),
            key=lambda source: counts[source][code] < PURE_SHARE * counts[source].sum(),
        )
        least = 2 if len(members) >= 4 else 1 if len(members) >= 2 else 0
        test += spread_pick(members, styles, least)
    test += [source for source in order if source not in test][: max(0, n_test - len(test))]
    return set(test)


def build_dataset(
    clips: Sequence[tuple[str, Trajectory]], params: FeaturesParams, variant: str
) -> FeatureDataset:
    """Features of every clip, split by source clip, normalised with training statistics."""
    if not clips:
        raise PimannError(params.input, "no clips to build features from")
    rates = {float(t.rate_hz) for _, t in clips}
    if len(rates) != 1:
        raise PimannError(params.input, f"clips have different rates {sorted(rates)} Hz")
    layout = window_layout(params, rates.pop(), variant)
    test_sources = split_sources([t for _, t in clips], params.test_fraction, params.split_seed)
    clips = with_time_reversed(clips, params.time_reversed, test_sources)
    names = [name for name, _ in clips]
    sources = [t.source for _, t in clips]
    with_contacts = all(t.contacts is not None for _, t in clips)
    if not with_contacts:
        log.info("not every clip has contacts: the dataset carries none")
    margin = round(params.contact_margin_s * layout.rate_hz)
    parts: dict[bool, list[tuple[np.ndarray, ...]]] = {False: [], True: []}
    short = []
    for k, (name, trajectory) in enumerate(clips):
        x, y, steps = clip_features(trajectory, layout)
        if len(steps) == 0:
            log.debug("clip %s (%d frames) is shorter than the windows", name, len(trajectory))
            short.append(name)
        origin = np.stack([np.full(len(steps), k), steps], axis=1)
        contacts = np.zeros((len(steps), 2), bool)
        if with_contacts:
            contacts = settled_contacts(trajectory.contacts, margin)[steps]
        parts[trajectory.source in test_sources].append((x, y, origin, contacts))

    def stack(side: bool) -> tuple[np.ndarray, ...]:
        items = parts[side] or [
            (
                np.empty((0, layout.input_dim)),
                np.empty((0, layout.output_dim)),
                np.empty((0, 2)),
                np.empty((0, 2)),
            )
        ]
        x, y, origin, contacts = (np.concatenate(a) for a in zip(*items, strict=True))
        return x, y, origin.astype(np.int64), contacts.astype(bool) if with_contacts else None

    if short:
        log.info("%d of %d clips are shorter than the windows: no samples", len(short), len(clips))
    x_train, y_train, train_origin, train_contacts = stack(False)
    x_test, y_test, test_origin, test_contacts = stack(True)
    if len(x_train) == 0 or len(x_test) == 0:
        raise PimannError(
            params.input, f"empty split: {len(x_train)} train, {len(x_test)} test samples"
        )
    stats = Normalisation.fit(x_train, y_train)
    standing = data_standing(t for _, t in clips if t.source not in test_sources)
    log.info("standing pose (%s): generation starts from it", standing.origin)
    return FeatureDataset(
        x_train=stats.normalise_x(x_train).astype(np.float32),
        y_train=stats.normalise_y(y_train).astype(np.float32),
        x_test=stats.normalise_x(x_test).astype(np.float32),
        y_test=stats.normalise_y(y_test).astype(np.float32),
        stats=stats,
        layout=layout,
        clips=names,
        sources=sources,
        train_origin=train_origin,
        test_origin=test_origin,
        train_contacts=train_contacts,
        test_contacts=test_contacts,
        standing=standing.to_json(),
    )

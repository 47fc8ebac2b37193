"""How a gait's contacts look, rollouts beside the data's clips: the shape behind the sliding.

The sliding metric says how much a foot in contact moves; these say how, measured alike on
generated rollouts and on the retargeted clips they learn from (the evaluate rule's contacts
on the sole origins, as the position-level sliding counts them):

- `leg_step_high_share`: the share of the 12 leg joints' frame-to-frame step energy between
  6 and 15 Hz (above a gait's first harmonics, below the Nyquist rate of the 30 fps sources,
  whose resampling puts kinks higher up): crisp lifts and touchdowns carry it, a low-passed
  gait has none;
- `contact_tilt_deg`: the median tilt of a sole in contact (0 for a flat foot);
- `contact_yaw_rate`: the mean |yaw rate| of a sole in contact (rad/s), split into the base's
  (`base_yaw_rate`, the same frames) and the leg's own (`leg_yaw_rate`, sole less base): a
  sole that holds its heading has a leg that turns against the base;
- `contact_horizontal_speed`: the mean horizontal speed of a sole origin in contact (m/s);
- `double_support_share`: the share of frames with both soles in contact;
- `stance_travel`: the horizontal distance a sole origin covers while in contact, per stance
  (m): where the sliding's position level comes from, summed over each stance (a foot that
  skims the floor as it lifts or lands travels in contact);
- `swing_peak_height`: the median peak height of a sole origin over its swings (runs out of
  contact inside the clip, m): a low swing spends more of its travel near the floor.

`python -m diagnostics.gait_shape results/rollouts/w10 [...] --class forward` prints the
medians over the steered (`--unsteered`: unsteered) rollouts of the benchmark clips whose
majority class is the one asked, in a split, every seed, beside the data's clips themselves.
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pandas as pd

from pimann.core.contacts import true_runs
from pimann.core.params import Params, load_params
from pimann.core.paths import REPO_ROOT
from pimann.core.robot import LEG_JOINTS, Robot, load_robot
from pimann.core.rollout_files import HELD_OUT, find_rollouts
from pimann.core.rotations import quaternion_xyzw_matrices, tilt_of, yaw_of
from pimann.core.trajectory import Trajectory, read_trajectory
from pimann.evaluate.metrics import analyse
from pimann.generate.benchmark_clips import benchmark_clips
from pimann.learn.motion_classes import class_counts, majority_class

HIGH_BAND_HZ = (6.0, 15.0)
COLUMNS = [
    "leg_step_high_share",
    "contact_tilt_deg",
    "contact_yaw_rate",
    "base_yaw_rate",
    "leg_yaw_rate",
    "contact_horizontal_speed",
    "double_support_share",
    "stance_travel",
    "swing_peak_height",
]


def _rate(angles: np.ndarray, time: np.ndarray) -> np.ndarray:
    """Time derivative of unwrapped angles (T, ...), central differences."""
    return np.gradient(np.unwrap(angles, axis=0), time, axis=0)


def high_band_share(
    steps: np.ndarray, dt: float, band: tuple[float, float] = HIGH_BAND_HZ
) -> float:
    """Share of the energy of steps (T, J) (each column less its mean) in a frequency band."""
    spectrum = np.square(np.abs(np.fft.rfft(steps - steps.mean(axis=0), axis=0))).sum(axis=1)
    frequencies = np.fft.rfftfreq(len(steps), dt)
    total = spectrum.sum()
    inside = (frequencies >= band[0]) & (frequencies < band[1])
    return float(spectrum[inside].sum() / total) if total > 0 else float("nan")


def stance_and_swing(positions: np.ndarray, contact: np.ndarray) -> tuple[float, float]:
    """(mean horizontal travel per stance, median swing peak height) of sole origins
    `positions` (T, 2, 3) under `contact` (T, 2); NaN where there is no stance or no swing
    inside the clip."""
    travel, peaks = [], []
    for foot in range(contact.shape[1]):
        steps = np.linalg.norm(np.diff(positions[:, foot, :2], axis=0), axis=1)
        travel += [steps[start : stop - 1].sum() for start, stop in true_runs(contact[:, foot])]
        peaks += [
            positions[start:stop, foot, 2].max()
            for start, stop in true_runs(~contact[:, foot])
            if start > 0 and stop < len(contact)
        ]
    return (
        float(np.mean(travel)) if travel else float("nan"),
        float(np.median(peaks)) if peaks else float("nan"),
    )


def gait_shape(trajectory: Trajectory, robot: Robot, params: Params) -> dict[str, float]:
    """The `COLUMNS` of one trajectory (module docstring)."""
    a = analyse(trajectory, robot, params.evaluate, params.contacts, file_contacts=False)
    contact = a.origin_contacts
    steps = np.diff(np.asarray(trajectory.joint_positions)[:, LEG_JOINTS], axis=0)
    base_yaw = yaw_of(quaternion_xyzw_matrices(trajectory.base_quaternion_xyzw))
    base_rate = np.repeat(_rate(base_yaw, a.time)[:, None], 2, axis=1)
    sole_rate = _rate(yaw_of(a.feet.rotations), a.time)
    velocities = a.velocities("position", "local_world_aligned")

    def in_contact(values: np.ndarray, over=np.mean) -> float:
        return float(over(values[contact])) if contact.any() else float("nan")

    stance_travel, swing_peak = stance_and_swing(a.feet.positions, contact)

    return {
        "leg_step_high_share": high_band_share(steps, float(np.mean(np.diff(a.time)))),
        "contact_tilt_deg": in_contact(np.degrees(tilt_of(a.feet.rotations)), np.median),
        "contact_yaw_rate": in_contact(np.abs(sole_rate)),
        "base_yaw_rate": in_contact(np.abs(base_rate)),
        "leg_yaw_rate": in_contact(np.abs(sole_rate - base_rate)),
        "contact_horizontal_speed": in_contact(np.linalg.norm(velocities[..., :2], axis=-1)),
        "double_support_share": float(contact.all(axis=1).mean()),
        "stance_travel": stance_travel,
        "swing_peak_height": swing_peak,
    }


def compare(
    rollout_dirs: Sequence[str | Path],
    motion_class: str,
    split: str,
    params: Params,
    steering: bool = True,
) -> pd.DataFrame:
    """Median `COLUMNS` per rollouts folder (its rollouts, steered or not, of the benchmark
    clips in `split` whose majority class is `motion_class`, every seed) and of those clips
    in the data, with their counts."""
    robot = load_robot("retarget")
    clips = [
        clip
        for clip in benchmark_clips(REPO_ROOT / params.features.input, params)
        if clip.split == split and majority_class(class_counts(clip.trajectory)) == motion_class
    ]
    scenarios = {clip.scenario for clip in clips}
    rows = []
    for folder in rollout_dirs:
        model = Path(folder).name
        paths = [
            path
            for key, path in find_rollouts(Path(folder).parent)
            if key.model == model and key.steering == steering and key.scenario in scenarios
        ]
        rows.append(_medians(str(folder), [read_trajectory(p) for p in paths], robot, params))
    rows.append(_medians("data", [clip.trajectory for clip in clips], robot, params))
    return pd.DataFrame(rows)


def _medians(label: str, trajectories: list[Trajectory], robot: Robot, params: Params) -> dict:
    shapes = pd.DataFrame([gait_shape(t, robot, params) for t in trajectories], columns=COLUMNS)
    return {"trajectories": label, "count": len(shapes), **shapes.median().to_dict()}


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "rollouts", nargs="+", help="rollout folders of models, results/rollouts/w10"
    )
    parser.add_argument("--class", dest="motion_class", default="forward")
    parser.add_argument("--split", default=HELD_OUT, help="held_out | training")
    parser.add_argument("--unsteered", action="store_true", help="the rollouts without steering")
    args = parser.parse_args(argv)
    params = load_params()
    table = compare(args.rollouts, args.motion_class, args.split, params, not args.unsteered)
    with pd.option_context("display.width", 200, "display.max_columns", None):
        print(table.round(3).to_string(index=False))


if __name__ == "__main__":
    main()

"""Teacher-forced response per motion class: does a trained model predict the data's velocity?

Fed the data's own inputs, a model's first output sample (the base velocity of the next
frame, in its base frame: not an input column) should match the data's, and so should its
legs' joint steps s_i - s_{i-1}. Where it does and a rollout still fails,
the rollout loop is the cause (how it starts, what it feeds back); where it does not, the
training is. Run after `dvc repro` (it reads models/ and data/features):

    python -m diagnostics.teacher_forcing [--models models] [--samples 20000]

prints, per model seed and motion class (pimann.learn.motion_classes of the sample's frame), the
mean true and predicted forward and lateral base velocity and the least-squares slope of the
prediction on the truth (1: follows the data; 0: ignores it); and on the samples in single
support (the data's contact flags) the same for the contact leg's share of the sole's forward
velocity, (J_SF^B)^-1 J_SF^s sdot along the base's x (pimann.learn.physics_loss), which on a still
foot cancels the base's forward velocity: L_B charges their sum, so where a model predicts a
small base velocity this tells whether its legs shrank with it; and the slope of the
predicted leg joint steps on the data's (`leg_step_slope`: 1, the legs move as the data's);
and L_F (`feet_true`, `feet_pred`: the other sole's motion relative to the lower one near the
ground over the frame, `relative_sole_motion`, from the input's joints to the
data's and to the predicted ones): how far one step from the data's state moves the other
sole. It does not predict a rollout's sliding: trained with less dropout, a model halves it
and its rollouts slide more (docs/walking_directions.md). Beside
it, the same with the joints moved by the predicted velocities instead, s_{i-1} + dt sdot_i
(`feet_sdot`), and the slope of those steps on the data's (`sdot_step_slope`).
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pandas as pd
import torch

from pimann.core.errors import PimannError
from pimann.core.params import load_params
from pimann.core.paths import REPO_ROOT, repo_path
from pimann.core.robot import LEG_JOINTS
from pimann.core.trajectory import iter_collection
from pimann.learn.dataset import read_dataset
from pimann.learn.features import REVERSED_SUFFIX, time_reversed
from pimann.learn.kinematics_torch import rotation_vee
from pimann.learn.model_files import model_seeds
from pimann.learn.motion_classes import CLASSES, motion_classes
from pimann.learn.physics_loss import PhysicsInformedLoss
from pimann.learn.training_loss import TrainingLoss

# the next frame's base velocity (y_i's window is of frame i + 1: not an input column)
OUTPUTS = ("base_linear_future[0].x", "base_linear_future[0].y")


def sample_classes(collection: Path, clips: list[str], origin: np.ndarray) -> np.ndarray:
    """(N,) motion class name of each sample's frame (origin: clip index, step); a clip the
    features added time-reversed (`<name>~reversed`) is classed as played backward."""
    trajectories = dict(iter_collection(collection))
    by_name = {name: motion_classes(t) for name, t in trajectories.items()}
    for name in set(clips) - set(by_name):
        original = trajectories.get(name.removesuffix(REVERSED_SUFFIX))
        if name.endswith(REVERSED_SUFFIX) and original is not None:
            by_name[name] = motion_classes(time_reversed(original))
    return np.array([CLASSES[by_name[clips[c]][step]] for c, step in origin])


def _slope(truth: np.ndarray, prediction: np.ndarray) -> float:
    centred = truth - truth.mean()
    denominator = float(centred @ centred)
    return float(centred @ (prediction - prediction.mean())) / denominator if denominator else 0.0


def input_joints(layout, stats, x: np.ndarray) -> np.ndarray:
    """(N, 26) s_{i-1}, the joints of the normalised inputs `x`, in radians."""
    xs = layout.x_slices["joints"]
    return x[:, xs] * stats.x_std[xs] + stats.x_mean[xs]


def output_part(layout, stats, y: np.ndarray, name: str) -> np.ndarray:
    """(N, ...) the output block `name` of normalised outputs `y` (the data's or a
    prediction) in physical units."""
    ys = layout.y_slices[name]
    return y[:, ys] * stats.y_std[ys] + stats.y_mean[ys]


def leg_joint_steps(layout, stats, x: np.ndarray, y: np.ndarray, predicted: np.ndarray):
    """(truth, prediction) (N, legs): the leg joints' step s_i - s_{i-1} of the data's output
    and of the predicted one from the same input (normalised x, y, predicted; radians)."""
    before = input_joints(layout, stats, x)
    truth = output_part(layout, stats, y, "joints") - before
    prediction = output_part(layout, stats, predicted, "joints") - before
    return truth[:, LEG_JOINTS], prediction[:, LEG_JOINTS]


def contact_leg_velocity(
    loss: TrainingLoss, y: np.ndarray, contacts: np.ndarray | None
) -> np.ndarray:
    """(N,) the contact leg's share of its sole's forward velocity (base frame) in the
    normalised outputs `y`; NaN outside single support or without contact flags."""
    if contacts is None:
        return np.full(len(y), np.nan)
    with torch.no_grad():
        terms = loss.pi_terms(torch.as_tensor(y, dtype=torch.float32))
        feet, _ = loss.physics.foot_twists(terms["joints"], terms["joint_velocities"])
    left = torch.as_tensor(contacts[:, 0])
    share = torch.where(left, feet[:, 0, 0], feet[:, 1, 0]).numpy()
    return np.where(contacts.sum(axis=1) == 1, share, np.nan)


def near_ground_weight(gap: torch.Tensor, height: float) -> torch.Tensor:
    """How much a sole `gap` metres above the lower one counts as down: sigmoid((height - gap)
    4 / height), 0.98 on the ground, 0.5 at the contact height, 0.02 at twice it."""
    return torch.sigmoid((height - gap) * (4.0 / height))


def relative_sole_motion(
    physics: PhysicsInformedLoss,
    previous_joints: torch.Tensor,
    joints: torch.Tensor,
    base_rpy: torch.Tensor,
    dt: float,
    height: float,
) -> torch.Tensor:
    """(...,) L_F: how fast the other sole moves relative to the lower one from one frame's
    joints to the next, weighted by how near the ground it is.

    Both soles still on the ground keep their relative pose: the other sole's pose in the
    lower sole's frame, R_l^T (p_o - p_l) and R_l^T R_o, is the same at s_{i-1} and s_i.
    Its change over dt (m/s, and rad/s by the small-angle vee of the relative rotation),
    squared and averaged over the 6 components, is weighted by
    sigmoid((height - gap) 4 / height), the gap the other sole's height above the lower
    one at s_i (no gradient), `near_ground_weight`.
    """
    now, before = physics.kinematics.chains(joints), physics.kinematics.chains(previous_joints)
    heights = physics.sole_heights(base_rpy, now.frame_positions)
    left = physics.lower_is_left(heights).unsqueeze(-1)
    weight = near_ground_weight((heights[..., 0] - heights[..., 1]).abs(), height)

    def relative(chain):
        p, r = chain.frame_positions, chain.frame_rotations
        lower_p = torch.where(left, p[..., 0, :], p[..., 1, :])
        other_p = torch.where(left, p[..., 1, :], p[..., 0, :])
        lower_r = torch.where(left.unsqueeze(-1), r[..., 0, :, :], r[..., 1, :, :])
        other_r = torch.where(left.unsqueeze(-1), r[..., 1, :, :], r[..., 0, :, :])
        lower_t = lower_r.transpose(-1, -2)
        return (lower_t @ (other_p - lower_p).unsqueeze(-1)).squeeze(-1), lower_t @ other_r

    p1, r1 = relative(now)
    p0, r0 = relative(before)
    angle = rotation_vee(r0.transpose(-1, -2) @ r1)
    rate = torch.cat((p1 - p0, angle), -1) / dt
    return weight * rate.square().mean(-1)


def feet_motion(
    loss: TrainingLoss,
    layout,
    stats,
    x: np.ndarray,
    y: np.ndarray,
    joints_from: np.ndarray,
    height: float,
) -> np.ndarray:
    """(N,) L_F of each sample (pimann.learn.physics_loss): the other sole's motion relative
    to the lower one near the ground, from the input's joints s_{i-1} to the joints of
    `joints_from` (normalised outputs: the data's or a prediction), at the data's base
    orientation so that both are weighted alike."""
    before = input_joints(layout, stats, x)
    after = output_part(layout, stats, joints_from, "joints")
    angles = output_part(layout, stats, y, "base_rpy")
    with torch.no_grad():
        motion = relative_sole_motion(
            loss.physics,
            *(torch.as_tensor(a, dtype=torch.float32) for a in (before, after, angles)),
            dt=1.0 / layout.rate_hz,
            height=height,
        )
    return motion.numpy()


def integrated_joints(layout, stats, x: np.ndarray, predicted: np.ndarray) -> np.ndarray:
    """`predicted` (normalised) with its joints replaced by s_{i-1} + dt sdot_i, the input's
    joints moved by the predicted joint velocities."""
    ys = layout.y_slices["joints"]
    before = input_joints(layout, stats, x)
    sdot = output_part(layout, stats, predicted, "joint_velocities")
    out = predicted.copy()
    out[:, ys] = (before + sdot / layout.rate_hz - stats.y_mean[ys]) / stats.y_std[ys]
    return out


def class_response(models_dir: Path, collection: Path, samples: int) -> pd.DataFrame:
    """One row per model seed, split (train subset / test) and motion class."""
    from pimann.learn.model_files import load_model

    rows = []
    cache: dict[str, tuple] = {}
    height = load_params().contacts.on_height
    for seed, folder in model_seeds(models_dir).items():
        model, layout, stats, meta = load_model(folder)
        dataset_path = repo_path(meta["dataset"])
        if str(dataset_path) not in cache:
            dataset = read_dataset(dataset_path)
            take = np.linspace(0, len(dataset.x_train) - 1, min(samples, len(dataset.x_train)))
            take = take.astype(int)
            train_contacts = dataset.train_contacts
            parts = {
                "train": (
                    dataset.x_train[take],
                    dataset.y_train[take],
                    dataset.train_origin[take],
                    None if train_contacts is None else train_contacts[take],
                ),
                "test": (
                    dataset.x_test,
                    dataset.y_test,
                    dataset.test_origin,
                    dataset.test_contacts,
                ),
            }
            classes = {
                split: sample_classes(collection, dataset.clips, origin)
                for split, (_, _, origin, _) in parts.items()
            }
            # the data's own leg shares, once per dataset: its stats are the models' own
            loss = TrainingLoss(
                dataset.layout,
                dataset.stats,
                torch.device("cpu"),
                pi_configuration="predicted",
                pi_gradient="both",
            )
            leg_truths = {
                split: contact_leg_velocity(loss, y, contacts)
                for split, (_, y, _, contacts) in parts.items()
            }
            feet_truths = {
                split: feet_motion(loss, dataset.layout, dataset.stats, x, y, y, height)
                for split, (x, y, _, _) in parts.items()
            }
            cache[str(dataset_path)] = (
                dataset.layout.names("y"),
                parts,
                classes,
                loss,
                leg_truths,
                feet_truths,
            )
        names, parts, classes, loss, leg_truths, feet_truths = cache[str(dataset_path)]
        columns = [names.index(name) for name in OUTPUTS]
        for split, (x, y, _, contacts) in parts.items():
            with torch.no_grad():
                predicted = model(torch.as_tensor(x, dtype=torch.float32)).numpy()
            truth = y[:, columns] * stats.y_std[columns] + stats.y_mean[columns]
            prediction = predicted[:, columns] * stats.y_std[columns] + stats.y_mean[columns]
            leg_truth = leg_truths[split]
            leg_prediction = contact_leg_velocity(loss, predicted, contacts)
            step_truth, step_prediction = leg_joint_steps(layout, stats, x, y, predicted)
            feet_prediction = feet_motion(loss, layout, stats, x, y, predicted, height)
            integrated = integrated_joints(layout, stats, x, predicted)
            feet_integrated = feet_motion(loss, layout, stats, x, y, integrated, height)
            _, sdot_step = leg_joint_steps(layout, stats, x, y, integrated)
            for name in CLASSES:
                mask = classes[split] == name
                if mask.sum() < 50:
                    continue
                single = mask & np.isfinite(leg_truth)
                leg = {"leg_true": np.nan, "leg_pred": np.nan, "leg_slope": np.nan}
                if single.sum() >= 50:
                    true_leg, predicted_leg = leg_truth[single], leg_prediction[single]
                    leg = {
                        "leg_true": true_leg.mean(),
                        "leg_pred": predicted_leg.mean(),
                        "leg_slope": _slope(true_leg, predicted_leg),
                    }
                rows.append(
                    {
                        "model": models_dir.name,
                        "seed": seed,
                        "split": split,
                        "class": name,
                        "samples": int(mask.sum()),
                        "vx_true": truth[mask, 0].mean(),
                        "vx_pred": prediction[mask, 0].mean(),
                        "vy_true": truth[mask, 1].mean(),
                        "vy_pred": prediction[mask, 1].mean(),
                        "vx_slope": _slope(truth[mask, 0], prediction[mask, 0]),
                        "vy_slope": _slope(truth[mask, 1], prediction[mask, 1]),
                        **leg,
                        "leg_step_slope": _slope(
                            step_truth[mask].ravel(), step_prediction[mask].ravel()
                        ),
                        "feet_true": feet_truths[split][mask].mean(),
                        "feet_pred": feet_prediction[mask].mean(),
                        "feet_sdot": feet_integrated[mask].mean(),
                        "sdot_step_slope": _slope(
                            step_truth[mask].ravel(), sdot_step[mask].ravel()
                        ),
                    }
                )
    return pd.DataFrame(rows)


def model_folders(root: Path) -> list[Path]:
    """The training outputs under `root`: itself when it is one (models/w10, its seeds'
    folders inside), else its sub-folders that are (models/)."""
    if any(root.glob("*/meta.json")):
        return [root]
    folders = sorted(p for p in root.iterdir() if p.is_dir() and any(p.glob("*/meta.json")))
    if not folders:
        raise PimannError(root, "no trained models here (models/ or one of its folders)")
    return folders


def add_models_argument(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--models",
        type=Path,
        default=REPO_ROOT / "models",
        help="models/ or one training output in it, e.g. models/w10",
    )


def table_over_models(
    tool: str, models: Path, table_of: Callable[[list[Path]], pd.DataFrame]
) -> pd.DataFrame | None:
    """`table_of` the training outputs under `models` (`model_folders`); None after the one
    line on stderr that names the bad input."""
    try:
        if not models.is_dir():
            raise PimannError(models, "not a folder")
        return table_of(model_folders(models))
    except PimannError as error:
        print(f"{tool}: {error}", file=sys.stderr)
        return None


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_models_argument(parser)
    parser.add_argument("--samples", type=int, default=20000, help="training samples used")
    args = parser.parse_args(argv)

    def responses(folders: list[Path]) -> pd.DataFrame:
        collection = REPO_ROOT / load_params().features.input
        frames = [class_response(folder, collection, args.samples) for folder in folders]
        return pd.concat(frames, ignore_index=True)

    table = table_over_models("teacher_forcing", args.models, responses)
    if table is None:
        return 2
    with pd.option_context("display.width", 160, "display.max_rows", 500):
        print(table.round(2).to_string(index=False))
    return 0


if __name__ == "__main__":
    sys.exit(main())

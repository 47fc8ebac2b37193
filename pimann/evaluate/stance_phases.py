"""Where in a stance the support feet slide: just after touchdown, mid-stance or before lift-off.

A stance is a run of one foot's contact frames. Its first frames (`EDGE_S`) after a touchdown
the trajectory shows are the touchdown window, its last ones before a lift-off it shows the
lift-off window (lift-off wins where a short stance has both); the rest is mid-stance. A stance
already under way at the first frame has no touchdown window, one still on at the last frame no
lift-off window. The share of a sliding sum in each window tells a foot that drags before it
lifts (lift-off share well above the window's share of the contact frames) from one that
creeps while it bears weight (mid-stance).
"""

from __future__ import annotations

import numpy as np

PHASES = ("touchdown", "mid", "liftoff")
EDGE_S = 0.1  # s: the touchdown and lift-off windows (5 frames at 50 Hz)
SHARE_METRICS = ("linear", "linear_position")  # the pimann.evaluate.metrics.SLIDING names split
_NONE, _TOUCHDOWN, _MID, _LIFTOFF = range(4)


def stance_phases(contacts: np.ndarray, edge_frames: int) -> np.ndarray:
    """(T, F) labels of (T, F) contacts: 0 no contact, 1 touchdown, 2 mid-stance, 3 lift-off."""
    contacts = np.asarray(contacts, dtype=bool)
    frames = len(contacts)
    index = np.broadcast_to(np.arange(frames)[:, None], contacts.shape)
    # the last frame without contact at or before each frame, the first one at or after it
    last_free = np.maximum.accumulate(np.where(contacts, -1, index), axis=0)
    next_free = np.minimum.accumulate(np.where(contacts, frames, index)[::-1], axis=0)[::-1]
    touchdown = contacts & (last_free >= 0) & (index - last_free <= edge_frames)
    liftoff = contacts & (next_free < frames) & (next_free - index <= edge_frames)
    labels = np.where(contacts, _MID, _NONE)
    labels[touchdown] = _TOUCHDOWN
    labels[liftoff] = _LIFTOFF
    return labels


def _counted_labels(contacts: np.ndarray, rate_hz: float, counted: np.ndarray | None) -> np.ndarray:
    """`stance_phases` at `EDGE_S`, frames outside `counted` relabelled as not in contact."""
    labels = stance_phases(contacts, max(1, round(EDGE_S * rate_hz)))
    if counted is None:
        return labels
    return np.where(np.asarray(counted, dtype=bool)[:, None], labels, _NONE)


def _shares(per_frame: np.ndarray, labels: np.ndarray) -> dict[str, float | None]:
    values = np.where(labels != _NONE, np.asarray(per_frame, dtype=float), 0.0)
    total, in_contact = values.sum(), int((labels != _NONE).sum())
    shares: dict[str, float | None] = {}
    for label, phase in enumerate(PHASES, start=_TOUCHDOWN):
        mask = labels == label
        shares[phase] = float(values[mask].sum() / total) if total > 0 else None
        shares[f"{phase}_frames"] = float(mask.sum() / in_contact) if in_contact else None
    return shares


def phase_shares(
    per_frame: np.ndarray,
    contacts: np.ndarray,
    rate_hz: float,
    counted: np.ndarray | None = None,
) -> dict[str, float | None]:
    """{phase: share of the contact-masked sum of `per_frame` (T, F)} (None: nothing slides),
    and {phase}_frames: the phase's share of the contact frames (what an even spread gives).

    `counted` (T,) bool: only these frames are summed (the phases still come from the whole
    trajectory, so a class boundary is no touchdown).
    """
    return _shares(per_frame, _counted_labels(contacts, rate_hz, counted))


def phase_share_metrics(
    per_frame: dict[str, np.ndarray],
    contacts: np.ndarray,
    rate_hz: float,
    counted: np.ndarray | None = None,
) -> dict[str, float | None]:
    """`support_rmse_<name>_<phase>_share` of each sliding metric's (T, F) per-frame RMS, and
    `contact_<phase>_frames_share`, as pimann.evaluate.metrics and pimann.evaluate.data_reference
    report them:
    the phases labelled once for all the metrics."""
    labels = _counted_labels(contacts, rate_hz, counted)
    out: dict[str, float | None] = {}
    for name, values in per_frame.items():
        shares = _shares(values, labels)
        out.update({f"support_rmse_{name}_{phase}_share": shares[phase] for phase in PHASES})
    out.update({f"contact_{phase}_frames_share": shares[f"{phase}_frames"] for phase in PHASES})
    return out

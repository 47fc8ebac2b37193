"""The gait phase of a clip from its contacts (beyond the paper: PFNN, Holden et al. 2017).

`features.gait_phase` adds the phase to the state the network sees and predicts, beside the
joints: (cos, sin) of the phase at i - 1 in x_i, at i in y_i, fed back as predicted in a
rollout. The phase is 0 (mod 2 pi) at every touchdown of the left foot and pi at every touchdown
of the right, and runs linearly between them, so that one stride is one turn whatever its
speed; a touchdown of the same foot as the previous one advances it a whole turn. A pause (a gap
between touchdowns longer than `step_s`) holds the phase still until `step_s` before the next
touchdown: standing does not advance it. Before the first touchdown the phase runs up to it over
`step_s` (from half a turn earlier); after the last it holds.
"""

from __future__ import annotations

import numpy as np

from pimann.core.errors import PimannError


def _flags(contacts: np.ndarray, step_s: float | None = None) -> np.ndarray:
    """(T, 2) boolean contact flags, or one clear error on a wrong shape or pause length."""
    if step_s is not None and step_s <= 0:
        raise PimannError(None, f"features.gait_phase_step_s must be positive, not {step_s}")
    contacts = np.asarray(contacts, dtype=bool)
    if contacts.ndim != 2 or contacts.shape[1] != 2:
        raise PimannError(None, f"contact flags of shape {contacts.shape}, not (T, 2)")
    return contacts


def touchdown_frames(contacts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(frames, feet): every touchdown (a foot's flag switching on) in time order; feet 0 left,
    1 right. A foot already down at frame 0 has no touchdown there; of two at one frame, the
    left's."""
    contacts = _flags(contacts)
    on = ~contacts[:-1] & contacts[1:]
    frames, feet = np.nonzero(on)
    order = np.lexsort((feet, frames))
    frames, feet = frames[order] + 1, feet[order]
    first = np.ones(len(frames), dtype=bool)  # both feet at one frame: the left's counts
    first[1:] = frames[1:] != frames[:-1]
    return frames[first], feet[first]


def gait_phase(contacts: np.ndarray, rate_hz: float, step_s: float) -> np.ndarray:
    """(T,) the unwrapped phase (radians, non-decreasing) of (T, 2) contact flags (left, right)
    at `rate_hz`; see the module docstring. A clip without a touchdown has phase 0 throughout."""
    contacts = _flags(contacts, step_s)
    frames, feet = touchdown_frames(contacts)
    time = np.arange(len(contacts)) / rate_hz
    if len(frames) == 0:
        return np.zeros(len(contacts))
    values = np.empty(len(frames))
    values[0] = np.pi * feet[0]
    # the next touchdown is half a turn on after the other foot's, a whole turn after its own
    values[1:] = np.pi * np.where(feet[1:] != feet[:-1], 1.0, 2.0)
    return _through_events(frames / rate_hz, np.cumsum(values), time, step_s)


def _through_events(
    at: np.ndarray, values: np.ndarray, time: np.ndarray, step_s: float
) -> np.ndarray:
    """The phase at `time` through the events' (time, value) knots: linear between events, held
    through a gap longer than `step_s` until `step_s` before the next event, run up to the first
    over `step_s` from half a turn earlier, held after the last."""
    knot_times, knot_values = [at[0] - step_s, at[0]], [values[0] - np.pi, values[0]]
    for k in range(1, len(at)):
        start = at[k] - min(at[k] - at[k - 1], step_s)
        if start > at[k - 1]:  # a pause: the phase waits
            knot_times.append(start)
            knot_values.append(values[k - 1])
        knot_times.append(at[k])
        knot_values.append(values[k])
    return np.interp(time, knot_times, knot_values)


def phase_vector(phase: np.ndarray) -> np.ndarray:
    """(..., 2) cos and sin of `phase` (...,): what the network sees (continuous over turns)."""
    phase = np.asarray(phase, dtype=float)
    return np.stack([np.cos(phase), np.sin(phase)], axis=-1)


def unit_phase(vector: np.ndarray) -> np.ndarray:
    """(..., 2 n) predicted (cos, sin) pairs, each put back on the unit circle (a rollout feeds
    them back); a zero pair becomes (1, 0)."""
    vector = np.asarray(vector, dtype=float)
    if vector.shape[-1] != 2:
        pairs = vector.reshape(*vector.shape[:-1], -1, 2)
        return unit_phase(pairs).reshape(vector.shape)
    norm = np.linalg.norm(vector, axis=-1, keepdims=True)
    unit = np.zeros_like(vector)
    unit[..., 0] = 1.0
    return np.where(norm > 1e-12, vector / np.where(norm > 1e-12, norm, 1.0), unit)

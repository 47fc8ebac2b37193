"""What the data set is made of: takes (files) of every mocap source, cut into clips.

A source (params `data.sources`) is a glob of files on one skeleton. Bandai Namco files are
named `dataset-N_<content>_<style>_NNN.bvh`; each has a JSON beside it with the content and
style as indices into the dataset's `cfg/content_label.txt` and `cfg/style_label.txt`. The
labels are the authority: a file whose name disagrees with its JSON is reported rather than
silently filed under the wrong content. Long takes are cut into clips, at standing pauses
where the take has them, so that a clip starts and ends standing like the paper's data.
"""

from __future__ import annotations

import dataclasses
import functools
import json
import re
from pathlib import Path

import numpy as np

from pimann.core.contacts import true_runs
from pimann.core.errors import PimannError
from pimann.core.params import DataParams, SkeletonParams, SourceParams
from pimann.core.paths import bandai_label_files, resolve_shared, shared_glob
from pimann.mocap.bvh import read_bvh
from pimann.mocap.human_motion import HumanMotion

_NAME = re.compile(r"^dataset-(\d+)_(.+)_([^_]+)_(\d+)$")
PAUSE_SPEED = 0.1  # m/s: the pelvis moves horizontally slower than this while standing ...
PAUSE_MIN_S = 0.5  # ... for at least this long: a standing pause, where a take is cut
SPEED_SMOOTHING_S = 0.25  # moving average of the pelvis speed (mocap jitter, sway)
GAIT_SMOOTHING_S = 1.0  # the same over about a gait cycle: walking against running
MIN_CLIP_S = 4.0  # shortest clip cut from a take (the feature window spans 2.2 s)


@dataclasses.dataclass(frozen=True)
class Take:
    """One file of a source: what to read it with and its labels (None when unlabelled)."""

    path: Path
    source: str  # the key of data.sources ("" for a file of no source)
    skeleton: SkeletonParams | None  # None: recognised from the joint names
    content: str | None
    style: str | None
    rate_hz: float | None = None  # overrides the file's frame rate
    clip_s: float | None = None  # longer takes are cut into clips
    max_speed: float | None = None  # m/s: faster stretches (running) are left out

    @property
    def name(self) -> str:
        return self.path.stem


@dataclasses.dataclass(frozen=True)
class Clip:
    """A time span of a take: frames start..stop-1, times from the take's first frame."""

    take: Take
    start_s: float  # time of the first frame
    stop_s: float  # time of the last frame
    name: str  # `<take stem>`, or `<take stem>_c<k>` when the take is cut


@functools.cache
def _labels(path: Path, prefix: str) -> tuple[str, ...]:
    """Label file lines without the `dataset-N_` prefix."""
    if not path.is_file():
        raise PimannError(path, "label file not found")
    return tuple(line.strip().removeprefix(prefix) for line in path.read_text().split("\n") if line)


def bandai_labels(bvh: Path) -> tuple[str, str]:
    """(content, style) of a Bandai Namco file from the JSON beside it, checked with its name."""
    match = _NAME.match(bvh.stem)
    if not match:
        raise PimannError(bvh, "name is not dataset-N_<content>_<style>_NNN")
    prefix = f"dataset-{int(match.group(1))}_"
    label_path, content_path, style_path = bandai_label_files(bvh)
    contents = _labels(content_path, prefix)
    styles = _labels(style_path, prefix)
    try:
        label = json.loads(label_path.read_text())
        content, style = contents[label["content"]], styles[label["style"]]
    except FileNotFoundError:
        raise PimannError(label_path, "label file not found") from None
    except (ValueError, KeyError, IndexError, TypeError) as error:
        raise PimannError(label_path, f"unreadable labels ({error!r})") from None
    if (content, style) != (match.group(2), match.group(3)):
        raise PimannError(
            label_path, f"labels {content}/{style} disagree with the file name {bvh.name}"
        )
    return content, style


def _take(path: Path, key: str, source: SourceParams, data: DataParams) -> Take:
    """A file of a source, with the source's skeleton, rate, cutting and the file's labels."""
    skeleton = None if source.skeleton == "auto" else data.skeletons[source.skeleton]
    labels = bandai_labels(path) if source.labels == "bandai_namco" else (None, None)
    return Take(
        path,
        key,
        skeleton,
        *labels,
        rate_hz=source.rate_hz,
        clip_s=source.clip_s,
        max_speed=source.max_speed,
    )


def source_takes(key: str, source: SourceParams, data: DataParams) -> list[Take]:
    """The takes of one source: its files, labelled and filtered, at most `max_takes`."""
    pattern = str(resolve_shared(source.path))
    paths = shared_glob(source.path)
    if not paths:
        raise PimannError(pattern, f"data.sources.{key}: the glob matches no file")
    if source.labels == "motion" and (source.contents is not None or source.styles is not None):
        raise PimannError(pattern, f"data.sources.{key}: contents/styles filter unlabelled files")
    takes = [
        take
        for take in (_take(p, key, source, data) for p in paths)
        if (source.contents is None or take.content in source.contents)
        and (source.styles is None or take.style in source.styles)
    ]
    if not takes:
        raise PimannError(
            pattern,
            f"data.sources.{key}: no file matches contents {source.contents} "
            f"styles {source.styles}",
        )
    if source.max_takes is not None and len(takes) > source.max_takes:
        takes = _spread(takes, source.max_takes, source.contents)
    return takes


def take_of(path: str | Path, data: DataParams) -> Take:
    """The take of one file: as the first source whose glob matches it reads it, else a
    whole file on a recognised skeleton at its own rate."""
    path = Path(path).resolve()
    for key, source in data.sources.items():
        if path.match(str(resolve_shared(source.path))):
            return _take(path, key, source, data)
    return Take(path, "", None, None, None)


def read_take(take: Take) -> HumanMotion:
    """The take's motion, read once (BVH; the skeleton and rate of its source)."""
    return read_bvh(take.path, take.skeleton, take.rate_hz)


def _spread(takes: list[Take], count: int, contents: list[str] | None) -> list[Take]:
    """`count` takes round-robin over (folder, content, style) groups, the k-th group of
    every content before the (k+1)-th: a small selection still sees every kind of motion."""
    groups: dict[tuple, list[Take]] = {}
    for take in takes:
        groups.setdefault((take.path.parent, take.content, take.style), []).append(take)
    order = contents or sorted({t.content for t in takes if t.content is not None})
    rank: dict[str | None, int] = {}
    keyed = []
    for (_, content, _), queue in groups.items():
        rank[content] = rank.get(content, -1) + 1
        position = order.index(content) if content in order else len(order)
        keyed.append((rank[content], position, queue))
    queues = [queue for *_, queue in sorted(keyed, key=lambda item: item[:2])]
    picked: list[Take] = []
    depth = 0
    while len(picked) < count:
        picked += [q[depth] for q in queues if depth < len(q)][: count - len(picked)]
        depth += 1
    return sorted(picked, key=lambda t: t.path)


def select_takes(data: DataParams) -> list[Take]:
    """Every source's takes, source by source in params order, files sorted by path.

    Clip names are take stems, so two takes with one stem (the HDF5 groups) are refused."""
    takes = [t for key, source in data.sources.items() for t in source_takes(key, source, data)]
    seen: dict[str, Take] = {}
    for take in takes:
        other = seen.setdefault(take.name, take)
        if other is not take:
            raise PimannError(take.path, f"same file name as {other.path}: clip names would clash")
    return takes


def pelvis_speed(motion: HumanMotion, window_s: float = SPEED_SMOOTHING_S) -> np.ndarray:
    """(T,) the pelvis's horizontal speed (m/s), a `window_s` moving average."""
    pelvis = motion.pelvis_position[:, :2]
    step = np.linalg.norm(np.diff(pelvis, axis=0), axis=1) / np.diff(motion.time)
    speed = np.append(step, step[-1])
    width = max(1, round(window_s * motion.rate_hz))
    padded = np.pad(speed, (width // 2, width - 1 - width // 2), mode="edge")
    return np.convolve(padded, np.ones(width) / width, mode="valid")


def pause_centres(motion: HumanMotion) -> np.ndarray:
    """Middle frames of the standing pauses: the pelvis's smoothed horizontal speed below
    PAUSE_SPEED for at least PAUSE_MIN_S."""
    if motion.n_frames < 3:
        return np.empty(0, int)
    runs = true_runs(pelvis_speed(motion) < PAUSE_SPEED)
    return np.array(
        [(a + b) // 2 for a, b in runs if motion.time[b - 1] - motion.time[a] >= PAUSE_MIN_S],
        dtype=int,
    )


def walking_spans(motion: HumanMotion, max_speed: float | None) -> list[tuple[int, int]]:
    """(start, stop) frame spans of the take where the pelvis is no faster than `max_speed`
    (the robot walks; a take's running is left out), each at least MIN_CLIP_S long."""
    if max_speed is None or motion.n_frames < 3:
        return [(0, motion.n_frames)]
    runs = true_runs(pelvis_speed(motion, GAIT_SMOOTHING_S) <= max_speed)
    return [(a, b) for a, b in runs if motion.time[b - 1] - motion.time[a] >= MIN_CLIP_S]


def clip_count(duration: float, clip_s: float | None) -> int:
    """How many clips cut_take makes of a take this long (known before reading it)."""
    return 1 if clip_s is None or duration <= clip_s else max(1, round(duration / clip_s))


def cut_take(motion: HumanMotion, clip_s: float | None) -> list[tuple[int, int]]:
    """(start, stop) frame spans covering the take, each about clip_s long (at least
    MIN_CLIP_S): evenly spaced cuts, each moved to the nearest standing pause within half a
    clip (the rest re-spread after it). A take no longer than clip_s stays whole."""
    n, duration = motion.n_frames, motion.duration
    n_clips = clip_count(duration, clip_s)
    if n_clips == 1:
        return [(0, n)]
    shortest = min(MIN_CLIP_S, duration / n_clips)
    time = motion.time - motion.time[0]
    pauses = time[pause_centres(motion)]
    cuts = [0.0]
    for k in range(1, n_clips):
        target = cuts[-1] + (duration - cuts[-1]) / (n_clips - k + 1)
        low = max(cuts[-1] + shortest, target - clip_s / 2)
        high = min(duration - (n_clips - k) * shortest, target + clip_s / 2)
        near = pauses[(pauses >= low) & (pauses <= high)]
        cuts.append(float(near[np.argmin(np.abs(near - target))]) if len(near) else target)
    frames = [*np.searchsorted(time, cuts).tolist(), n]
    return list(zip(frames[:-1], frames[1:], strict=True))


def take_clips(
    take: Take, motion: HumanMotion, clip_s: float | None, max_speed: float | None = None
) -> list[Clip]:
    """The take's clips: its walking spans (`walking_spans`) as cut_take cuts each, named
    `<stem>` when the take stays whole, else `<stem>_c<k>` from k = 1."""
    time = motion.time - motion.time[0]
    spans = [
        (start + a, start + b)
        for start, stop in walking_spans(motion, max_speed)
        for a, b in cut_take(slice_motion(motion, start, stop), clip_s)
    ]
    if spans == [(0, motion.n_frames)]:
        return [Clip(take, 0.0, float(time[-1]), take.name)]
    return [
        Clip(take, float(time[a]), float(time[b - 1]), f"{take.name}_c{k:02d}")
        for k, (a, b) in enumerate(spans, start=1)
    ]


def clip_motion(motion: HumanMotion, clip: Clip) -> HumanMotion:
    """The frames of `motion` (the clip's take) inside the clip's span."""
    time = motion.time - motion.time[0]
    start, stop = np.searchsorted(time, [clip.start_s, clip.stop_s], side="left")
    return slice_motion(motion, int(start), int(stop) + 1)


def slice_motion(motion: HumanMotion, start: int, stop: int) -> HumanMotion:
    """Frames start..stop-1 of a motion (timestamps kept), foot points included."""
    keep = slice(start, stop)
    return dataclasses.replace(
        motion,
        time=motion.time[keep],
        orientations=motion.orientations[keep],
        segment_positions=motion.segment_positions[keep],
        foot_points=None if motion.foot_points is None else motion.foot_points[keep],
    )

"""Which Bandai Namco clips the study uses: chosen by content and style from params.

Files are named `dataset-N_<content>_<style>_NNN.bvh`; each has a JSON beside it with the
content and style as indices into the dataset's `cfg/content_label.txt` and
`cfg/style_label.txt`. The labels are the authority: a file whose name disagrees with its
JSON is reported rather than silently filed under the wrong content.
"""

from __future__ import annotations

import dataclasses
import json
import re
from pathlib import Path

from pimann.errors import PimannError
from pimann.params import DataParams
from pimann.paths import resolve_shared

_NAME = re.compile(r"^dataset-(\d+)_(.+)_([^_]+)_(\d+)$")


@dataclasses.dataclass(frozen=True)
class Clip:
    path: Path
    dataset: int
    content: str
    style: str
    number: int

    @property
    def name(self) -> str:
        return self.path.stem


def _labels(path: Path, prefix: str) -> list[str]:
    """Label file lines without the `dataset-N_` prefix."""
    if not path.is_file():
        raise PimannError(path, "label file not found")
    return [line.strip().removeprefix(prefix) for line in path.read_text().split("\n") if line]


def dataset_clips(dataset_dir: Path) -> list[Clip]:
    """Every labelled clip of one dataset folder (holding `cfg/` and `data/`)."""
    clips = []
    for bvh in sorted((dataset_dir / "data").glob("*.bvh")):
        match = _NAME.match(bvh.stem)
        if not match:
            raise PimannError(bvh, "name is not dataset-N_<content>_<style>_NNN")
        number = int(match.group(1))
        prefix = f"dataset-{number}_"
        contents = _labels(dataset_dir / "cfg/content_label.txt", prefix)
        styles = _labels(dataset_dir / "cfg/style_label.txt", prefix)
        label_path = bvh.with_suffix(".json")
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
        clips.append(Clip(bvh, number, content, style, int(match.group(4))))
    return clips


def select_clips(data: DataParams) -> list[Clip]:
    """Clips whose content is in `data.contents` and style in `data.styles` (None: all),
    at most `data.max_clips` of them, spread over contents and styles rather than the
    alphabetically first ones, so a quick run still sees every kind of walking."""
    root = resolve_shared(data.mocap_root)
    folders = sorted(p for p in root.glob("*") if (p / "data").is_dir())
    if not folders:
        raise PimannError(root, "no dataset folder with a data/ subfolder")
    chosen = [
        clip
        for folder in folders
        for clip in dataset_clips(folder)
        if clip.content in data.contents and (data.styles is None or clip.style in data.styles)
    ]
    if not chosen:
        raise PimannError(root, f"no clip matches contents {data.contents} styles {data.styles}")
    if data.max_clips is not None and len(chosen) > data.max_clips:
        # round-robin over (dataset, content, style) groups: deterministic and balanced
        groups: dict[tuple, list[Clip]] = {}
        for clip in chosen:
            groups.setdefault((clip.dataset, clip.content, clip.style), []).append(clip)
        # interleave the contents: the k-th style group of every content before the (k+1)-th
        rank: dict[str, int] = {}
        keyed = []
        for key, queue in groups.items():
            rank[key[1]] = rank.get(key[1], -1) + 1
            keyed.append((rank[key[1]], data.contents.index(key[1]), queue))
        queues = [queue for _, _, queue in sorted(keyed, key=lambda item: item[:2])]
        picked: list[Clip] = []
        depth = 0
        while len(picked) < data.max_clips:
            picked += [q[depth] for q in queues if depth < len(q)][: data.max_clips - len(picked)]
            depth += 1
        chosen = sorted(picked, key=lambda c: c.name)
    return chosen

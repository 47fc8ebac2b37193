"""Writing rendered pictures to a file: a .png strip (frames in rows), a .gif or an .mp4.

Split from pimann.render.trajectory, which draws the pictures; the simulate stage's MuJoCo frames
(pimann.sim.video) are written the same way.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from pimann.core.atomic import atomic_path
from pimann.core.errors import PimannError

FORMATS = (".gif", ".mp4", ".png")
STRIP_COLUMNS = 4  # frames per row of a .png strip: 6 frames in one row made 5775 px
SEPARATOR = 3  # px of grey between the frames of a strip
SEPARATOR_GREY = 120
FILL_WHITE = 255  # the empty places of a strip's last row


def check_output(path: Path) -> str:
    """The picture format of `path` (.gif, .mp4, .png), or a PimannError naming the file."""
    suffix = path.suffix.lower()
    if suffix not in FORMATS:
        raise PimannError(
            path, f"unknown picture format {path.suffix or '(none)'!r}; use one of {FORMATS}"
        )
    if suffix == ".mp4":
        try:
            import imageio_ffmpeg  # noqa: F401
        except ImportError:
            raise PimannError(
                path, "writing .mp4 needs the imageio-ffmpeg package; use .gif or .png"
            ) from None
    return suffix


def strip_image(pictures: list[np.ndarray], columns: int = STRIP_COLUMNS) -> np.ndarray:
    """Equal-sized RGB pictures in rows of `columns`, left to right then top to bottom, with
    grey separators; a short last row is filled with white."""
    if not pictures:
        raise ValueError("no pictures for a strip")
    columns = max(1, min(columns, len(pictures)))
    height, width = pictures[0].shape[:2]
    rows = math.ceil(len(pictures) / columns)
    image = np.full(
        (rows * height + (rows - 1) * SEPARATOR, columns * width + (columns - 1) * SEPARATOR, 3),
        SEPARATOR_GREY,
        dtype=np.uint8,
    )
    for k in range(rows * columns):
        row, column = divmod(k, columns)
        top, left = row * (height + SEPARATOR), column * (width + SEPARATOR)
        tile = pictures[k][..., :3] if k < len(pictures) else FILL_WHITE
        image[top : top + height, left : left + width] = tile
    return image


def _write_strip(path: Path, pictures: list[np.ndarray], columns: int) -> None:
    import imageio.v3 as iio

    iio.imwrite(path, strip_image(pictures, columns), extension=".png")


def _write_gif(path: Path, frames: Iterator[np.ndarray], fps: float) -> None:
    """Pillow GIF with each frame quantised as it comes (1 byte a pixel held, not 3)."""
    from PIL import Image

    images = [
        Image.fromarray(f).quantize(
            colors=64, method=Image.Quantize.FASTOCTREE, dither=Image.Dither.NONE
        )
        for f in frames
    ]
    images[0].save(path, save_all=True, append_images=images[1:], duration=1000.0 / fps, loop=0)


def _write_mp4(path: Path, frames: Iterator[np.ndarray], fps: float) -> None:
    """Frames streamed to ffmpeg (H.264), never all held in memory."""
    import imageio.v2 as imageio

    with imageio.get_writer(
        path, format="FFMPEG", fps=fps, codec="libx264", quality=7, macro_block_size=2
    ) as writer:
        for frame in frames:
            writer.append_data(frame)


def write_pictures(
    output_path: Path,
    pictures: Iterator[np.ndarray],
    fps: float,
    columns: int = STRIP_COLUMNS,
) -> None:
    """Pictures to a .png strip (`columns` a row), a .gif or an .mp4 (by the suffix), written
    atomically."""
    suffix = check_output(output_path)
    with atomic_path(output_path) as tmp:
        if suffix == ".png":
            _write_strip(tmp, list(pictures), columns)
        elif suffix == ".gif":
            _write_gif(tmp, pictures, fps)
        else:
            _write_mp4(tmp, pictures, fps)

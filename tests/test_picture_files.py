"""Writing pictures (pimann.render.picture_files): strips laid out as documented, animations with
every frame, unknown formats refused before anything is written."""

from __future__ import annotations

import imageio.v3 as iio
import numpy as np
import pytest
from PIL import Image

from pimann.core.errors import PimannError
from pimann.render.picture_files import (
    FILL_WHITE,
    SEPARATOR,
    SEPARATOR_GREY,
    check_output,
    strip_image,
    write_pictures,
)

H, W = 10, 16


def _pictures(n):
    """Picture k is uniformly 20 (k + 1) in red, k in green, 7 in blue (RGBA: alpha dropped)."""
    pictures = []
    for k in range(n):
        p = np.zeros((H, W, 4), np.uint8)
        p[..., 0], p[..., 1], p[..., 2], p[..., 3] = 20 * (k + 1), k, 7, 255
        pictures.append(p)
    return pictures


def test_a_strip_puts_frames_left_to_right_then_down_with_separators():
    image = strip_image(_pictures(6), columns=4)
    rows, columns = 2, 4
    assert image.shape == (rows * H + SEPARATOR, columns * W + 3 * SEPARATOR, 3)
    for k in range(rows * columns):
        row, column = divmod(k, columns)
        tile = image[row * (H + SEPARATOR) :][:H, column * (W + SEPARATOR) :][:, :W]
        expected = [20 * (k + 1), k, 7] if k < 6 else [FILL_WHITE] * 3
        assert np.all(tile == expected), k
    assert np.all(image[H : H + SEPARATOR] == SEPARATOR_GREY)  # between the rows
    assert np.all(image[:H, W : W + SEPARATOR] == SEPARATOR_GREY)  # between the columns


def test_a_strip_of_fewer_frames_than_columns_is_one_row():
    image = strip_image(_pictures(2), columns=4)
    assert image.shape == (H, 2 * W + SEPARATOR, 3)
    with pytest.raises(ValueError):
        strip_image([])


def test_png_gif_and_mp4_are_written_with_every_frame(tmp_path):
    write_pictures(tmp_path / "s.png", iter(_pictures(5)), fps=10, columns=2)
    assert iio.imread(tmp_path / "s.png").shape[:2] == (3 * H + 2 * SEPARATOR, 2 * W + SEPARATOR)

    frames = [p[..., :3].copy() for p in _pictures(4)]
    write_pictures(tmp_path / "a.gif", iter(frames), fps=20)
    with Image.open(tmp_path / "a.gif") as gif:
        assert gif.n_frames == 4 and gif.info["duration"] == 50  # ms a frame at 20 fps
        gif.seek(3)
        red = np.asarray(gif.convert("RGB"))[..., 0]
        assert abs(int(np.median(red)) - 80) <= 4  # the last frame's colour, quantised

    write_pictures(tmp_path / "a.mp4", iter(frames), fps=10)
    import imageio.v2 as imageio

    with imageio.get_reader(tmp_path / "a.mp4", format="FFMPEG") as reader:
        video = [frame for frame in reader]
        assert reader.get_meta_data()["fps"] == 10
    assert len(video) == 4 and video[0].shape[:2] == (H, W)
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []


def test_an_unknown_format_is_named_and_nothing_is_written(tmp_path):
    with pytest.raises(PimannError, match=r"unknown picture format '\.jpg'"):
        write_pictures(tmp_path / "x.jpg", iter(_pictures(1)), fps=1)
    with pytest.raises(PimannError, match="none"):
        check_output(tmp_path / "noext")
    assert list(tmp_path.iterdir()) == []
    assert check_output(tmp_path / "X.PNG") == ".png"

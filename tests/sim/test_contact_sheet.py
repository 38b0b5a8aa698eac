"""tools/contact_sheet.py: tiles, captions' inputs, atomic PNG, one-line errors."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
from toolmod import load_tool

from edge.io import FrameWriter


@pytest.fixture(scope="module")
def cs():
    return load_tool("contact_sheet.py")


def _recording(path: Path, n: int = 5) -> Path:
    with FrameWriter(path) as wr:
        for i in range(n):
            d = np.full((171, 224), 0.3, np.float32)
            d[50:90, 60:120] = 0.25
            d[:5, :5] = 0.0
            d[70, 100] = 0.0  # an invalid object pixel
            lab = np.zeros((171, 224), np.uint8)
            lab[50:90, 60:120] = 1
            wr.write(i * 1000, d, label=lab, intrinsics=(200.0, 200.0, 111.5, 85.0))
    return path


def test_colorize_marks_invalid_black(cs):
    d = np.linspace(0.2, 0.4, 171 * 224).reshape(171, 224)
    d[0, 0] = 0.0
    d[1, 1] = np.nan
    img = cs.colorize_depth(d)
    assert img.shape == (171, 224, 3) and img.dtype == np.uint8
    assert not img[0, 0].any() and not img[1, 1].any()
    assert (img.reshape(-1, 3).sum(axis=1) > 0).sum() == 171 * 224 - 2


def test_sheet_grid_and_label_overlay(cs, tmp_path):
    rec = _recording(tmp_path / "r.mcap")
    out = tmp_path / "sheet.png"
    assert cs.main([str(rec), "--out", str(out), "--frames", "3", "--cols", "2", "--scale", "1"]) == 0
    img = cv2.imread(str(out))
    tile_h, tile_w, gap = 171 + cs.CAPTION_H, 224, 4
    assert img.shape == (2 * tile_h + 3 * gap, 2 * tile_w + 3 * gap, 3)
    assert not list(tmp_path.glob(".*tmp"))  # atomic write left no temp file
    first = img[gap : gap + 171, gap : gap + 224]
    assert not first[2, 2].any() and not first[70, 100].any()  # invalid pixels black, labelled or not
    d = np.full((171, 224), 0.3)
    d[50:90, 60:120] = 0.25
    d[:5, :5] = 0.0
    d[70, 100] = 0.0
    plain = cs.colorize_depth(d)
    assert (first[20, 200] == plain[20, 200]).all()  # floor: the plain colour map
    tinted = (0.6 * plain[70, 90] + 0.4 * np.array([40, 40, 255])).astype(np.uint8)
    assert (first[70, 90] == tinted).all() and not (tinted == plain[70, 90]).all()  # object: red tint
    # only the tiles asked for: the third slot of the second row stays background
    assert (img[gap + tile_h + gap + 50, gap + tile_w + gap + 50] == 16).all()


@pytest.mark.parametrize(
    "args, message",
    [
        (["--frames", "0"], "--frames must be >= 1"),
        (["--out", "x.jpg"], "must end in .png"),
    ],
)
def test_bad_arguments_are_one_line(cs, tmp_path, capsys, args, message):
    rec = _recording(tmp_path / "r.mcap", 1)
    argv = [str(rec), "--out", str(tmp_path / "s.png"), *args]
    assert cs.main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and len(err.splitlines()) == 1


def test_missing_recording(cs, tmp_path, capsys):
    assert cs.main([str(tmp_path / "nope.mcap"), "--out", str(tmp_path / "s.png")]) == 2
    assert "no such file" in capsys.readouterr().err

"""tools/sim_vs_real.py end to end on two simulated frames (needs the shared real capture)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from toolmod import load_tool

ROOT = Path(__file__).resolve().parents[2]
REAL = ROOT.parent / "shared" / "data" / "royale" / "royale_20200513_203219_0.ply"


@pytest.fixture(scope="module")
def tool():
    return load_tool("sim_vs_real.py")


@pytest.mark.slow
def test_figure_table_and_json(tool, tmp_path, capsys):
    if not REAL.exists():
        pytest.skip(f"{REAL} is absent (shared data lives at ../shared next to the repo)")
    from sim.importers import fit_intrinsics, read_ply
    from sim.realism import realism

    png, md = tmp_path / "f.png", tmp_path / "f.md"
    argv = ["--frames", "2", "--objects", "0", "20", "--png", str(png), "--md", str(md), "--json"]
    assert tool.main(argv) == 0
    out = json.loads(capsys.readouterr().out)
    assert png.stat().st_size < 300_000 and png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    cap = read_ply(REAL)
    k, _ = fit_intrinsics(cap.points, cap.valid)
    want = realism(cap.depth, k)
    assert out["real"]["invalid.fraction"] == pytest.approx(want.invalid.fraction)
    assert out["real"]["noise.sigma_patch"] == pytest.approx(want.noise.sigma_patch)
    assert len(out["sim_frames"]) == 2 and out["sim_index"] == 0
    text = md.read_text()
    assert f"| invalid pixels, % of frame | {want.invalid.fraction * 100:.2f} |" in text
    assert "tools/sim_vs_real.py --frames 2" in text
    vals = [out["sim_frames"][i]["invalid.fraction"] for i in range(2)]
    assert f"{np.mean(vals) * 100:.2f} ± {np.std(vals) * 100:.2f}" in text


def test_missing_real_capture_is_one_line(tool, tmp_path, capsys):
    argv = ["--real", str(tmp_path / "none.ply"), "--png", str(tmp_path / "f.png"), "--md", str(tmp_path / "f.md")]
    assert tool.main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert "real capture not found" in err and len(err.splitlines()) == 1

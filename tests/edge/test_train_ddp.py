"""``depthseg-train`` under ``torchrun --nproc-per-node 2`` (DDP, gloo on CPU) matches one process."""

from __future__ import annotations

import csv
import os
import subprocess
import sys
from pathlib import Path

import pytest
from test_train import _frames

from edge.io import FrameWriter
from edge.train.checkpoint import read_checkpoint

ROOT = Path(__file__).resolve().parents[2]
ARGS = ["--encoder", "vgg11", "--batch-norm", "--width", "0.0625", "--batch-size", "8", "--lr", "1e-2",
        "--threads", "1", "--seed", "0"]


def _write(path: Path, n: int, seed: int) -> None:
    """The frames of `test_train._frames` (tilted floor, raised boxes, dead corners) as a recording."""
    fs = _frames(n, seed)
    with FrameWriter(path) as fw:
        for i in range(n):
            fw.write(i * 1000, fs.depth[i], fs.label[i], (50.0, 50.0, 28.0, 20.0))


def _run(cmd: list[str]) -> None:
    env = dict(os.environ, PYTHONPATH=str(ROOT), OMP_NUM_THREADS="1")
    r = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-3000:]


def _torchrun(n: int) -> list[str]:
    return [sys.executable, "-m", "torch.distributed.run", "--standalone", f"--nproc-per-node={n}", "-m",
            "edge.train_cli"]


def _log(run: Path) -> list[dict[str, float]]:
    with open(run / "log.csv") as fh:
        return [{k: float(v) for k, v in row.items()} for row in csv.DictReader(fh)]


@pytest.mark.slow
@pytest.mark.parametrize("loss", [[], ["--jaccard", "0.5"], ["--boundary-weight", "2"], ["--precision", "bf16"]],
                         ids=["bce", "bce+jaccard", "bce+boundary", "bf16"])
def test_two_process_torchrun_matches_one_process_and_resumes(tmp_path, loss):
    _write(tmp_path / "train.mcap", 16, 0)
    _write(tmp_path / "val.mcap", 8, 1)
    data = ["--train-dir", str(tmp_path / "train.mcap"), "--val-dir", str(tmp_path / "val.mcap"), *loss]
    one, two = tmp_path / "one", tmp_path / "two"
    _run([sys.executable, "-m", "edge.train_cli", *data, *ARGS, "--epochs", "2", "--out", str(one)])
    _run([*_torchrun(2), *data, *ARGS, "--epochs", "2", "--out", str(two)])
    a, b = _log(one), _log(two)
    assert len(a) == len(b) == 2
    for key in ("train_loss", "val_loss"):
        assert abs(b[-1][key] - a[-1][key]) <= 0.01 * a[-1][key], (key, a, b)
    blob = read_checkpoint(two / "last.pt")
    assert blob["meta"]["training"]["ddp_world_size"] == 2
    assert not list(two.glob(".*.tmp"))  # one writer: no leftovers of a second rank

    _run([*_torchrun(2), *data, *ARGS, "--epochs", "3", "--out", str(two), "--resume"])
    assert [int(r["epoch"]) for r in _log(two)] == [1, 2, 3]
    assert read_checkpoint(two / "last.pt")["epoch"] == 3

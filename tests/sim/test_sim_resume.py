"""Kill a real depthseg-sim run mid-way, resume it, and compare with an uninterrupted run."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader

from edge.io import SIM_EPOCH_NS, TOPIC_DEPTH, iter_frames
from sim import cli, dataset

FRAMES, SHARD = 30, 3
LIGHT = {"scene": {"n_objects": [0, 6]}}  # quick frames: the test is about shards, not scenes


def _cmd(out: Path) -> list[str]:
    cfg = out.parent / "light.json"
    cfg.write_text(json.dumps(LIGHT))
    return [sys.executable, "-m", "sim.cli", "--out", str(out), "--frames", str(FRAMES), "--config", str(cfg),
            "--shard-frames", str(SHARD), "--workers", "2", "--seed", "3"]


def _complete(out: Path) -> set[str]:
    return {p.name for p in out.glob("frames_*.mcap")}


def _frames(out: Path):
    return {f.stamp_ns: f for f in iter_frames(out, with_clean=True)}


@pytest.mark.slow
def test_kill_and_resume_loses_and_duplicates_nothing(tmp_path):
    a = tmp_path / "killed"
    proc = subprocess.Popen(_cmd(a), start_new_session=True, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and proc.poll() is None:
        if a.exists() and _complete(a):
            break
        time.sleep(0.005)
    os.killpg(proc.pid, signal.SIGKILL)  # the run and its workers, like a power cut
    proc.wait()
    at_kill = _complete(a)
    assert 0 < len(at_kill) < FRAMES // SHARD, f"kill did not land mid-run: {len(at_kill)} shards complete"
    # nothing under a final name is partial: each complete shard holds exactly its frames
    for name in at_kill:
        with open(a / name, "rb") as fh:
            n = sum(1 for _ in make_reader(fh).iter_messages(topics=[TOPIC_DEPTH]))
        assert n == SHARD

    res = subprocess.run(_cmd(a) + ["--json"], capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr
    summary = json.loads(res.stdout)
    assert summary["resumed_shards"] == len(at_kill)
    assert summary["generated"] == FRAMES - SHARD * len(at_kill)
    assert not list(a.glob(".*.tmp"))  # temporaries of the killed run were cleared

    b = tmp_path / "straight"
    cfg = cli._load_config(str(tmp_path / "light.json"))
    dataset.simulate(b, frames=FRAMES, seed=3, workers=1, shard_frames=SHARD, config=cfg, show_progress=False)
    fa, fb = _frames(a), _frames(b)
    stamps = [f.stamp_ns for f in iter_frames(a)]
    assert len(stamps) == len(set(stamps)) == FRAMES  # no duplicates, no losses
    assert sorted(fa) == sorted(fb) == [SIM_EPOCH_NS + i * 22_222_222 for i in range(FRAMES)]
    for t in fa:
        np.testing.assert_array_equal(fa[t].depth, fb[t].depth)
        np.testing.assert_array_equal(fa[t].label, fb[t].label)
        np.testing.assert_array_equal(fa[t].clean, fb[t].clean)
        assert fa[t].scene == fb[t].scene


def test_resume_after_a_longer_request_replaces_the_short_last_shard(tmp_path):
    cfg = tmp_path / "c.json"
    cfg.write_text(json.dumps({"scene": {"n_objects": [0, 2]}}))
    c = cli._load_config(str(cfg))
    dataset.simulate(tmp_path / "o", frames=3, seed=1, workers=1, shard_frames=2, config=c, show_progress=False)
    s = dataset.simulate(tmp_path / "o", frames=5, seed=1, workers=1, shard_frames=2, config=c, show_progress=False)
    assert s["resumed_shards"] == 1 and s["removed_stale_shards"] == 1 and s["generated"] == 3
    assert [(f.stamp_ns - SIM_EPOCH_NS) // 22_222_222 for f in iter_frames(tmp_path / "o")] == [0, 1, 2, 3, 4]

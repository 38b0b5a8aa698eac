"""``depthseg-sim --ray``: same bytes as ``--workers``; a killed Ray worker loses and duplicates nothing."""

from __future__ import annotations

import json
import os
import re
import signal
import sys
import threading
import time
from pathlib import Path

import pytest

from edge.errors import DataError
from edge.io import iter_frames
from sim import cli, dataset
from sim.generate import SimConfig

FRAMES, SHARD, SEED = 12, 3, 3
LIGHT = SimConfig.from_dict({"scene": {"n_objects": [0, 6]}})  # quick frames: the tests are about shards
RUN_FIELDS = {"seconds"}  # per-shard wall time: the only run-dependent field of a shard's statistics
SUMMARY_RUN_FIELDS = {"seconds", "frames_per_second", "workers", "ray", "generated", "resumed_shards", "out"}


def _shards(out: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(out.glob("frames_*.mcap"))}


def _manifest(out: Path) -> dict:
    m = json.loads((out / "manifest.json").read_text())
    m["shards"] = {k: {f: v for f, v in s.items() if f not in RUN_FIELDS} for k, s in m["shards"].items()}
    m["summary"] = {k: v for k, v in m["summary"].items() if k not in SUMMARY_RUN_FIELDS}
    return m


def test_ray_missing_is_one_line_error(tmp_path, monkeypatch, capsys):
    monkeypatch.setitem(sys.modules, "ray", None)  # import ray -> ImportError
    rc = cli.main(["--out", str(tmp_path / "o"), "--frames", "3", "--ray"])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and "depthseg[ray]" in err[0]
    assert not (tmp_path / "o").exists()


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    out = tmp_path_factory.mktemp("workers") / "ref"
    dataset.simulate(out, FRAMES, seed=SEED, workers=1, config=LIGHT, shard_frames=SHARD, show_progress=False)
    return out


@pytest.fixture(scope="module")
def local_ray():
    ray = pytest.importorskip("ray")
    from sim.ray_runner import _connect

    started = _connect(ray, None, 2)
    yield ray
    if started:
        ray.shutdown()


def test_ray_run_is_byte_identical_to_workers_run(tmp_path, reference, local_ray):
    out = tmp_path / "ray"
    s = dataset.simulate(out, FRAMES, seed=SEED, workers=2, config=LIGHT, shard_frames=SHARD, ray="", show_progress=False)
    assert s["generated"] == FRAMES and s["ray"] == "local"
    assert _shards(out) == _shards(reference)
    assert _manifest(out) == _manifest(reference)


def test_killed_ray_worker_loses_and_duplicates_nothing_on_rerun(tmp_path, reference, local_ray, monkeypatch):
    from sim import ray_runner

    monkeypatch.setattr(ray_runner, "MAX_RETRIES", 0)  # no retry: the run must stop, the rerun finish it
    out = tmp_path / "killed"
    errors: list[BaseException] = []

    def go() -> None:
        try:
            dataset.simulate(out, FRAMES, seed=SEED, workers=2, config=LIGHT, shard_frames=SHARD, ray="",
                         show_progress=False)
        except BaseException as exc:  # noqa: BLE001 - handed to the test thread
            errors.append(exc)

    th = threading.Thread(target=go)
    th.start()
    tmp_re = re.compile(r"^\.frames_\d{8}_\d{8}\.mcap\.(\d+)\.tmp$")
    killed = None
    deadline = time.monotonic() + 60
    while killed is None and time.monotonic() < deadline and th.is_alive():
        for p in out.glob(".frames_*.tmp") if out.exists() else ():
            m = tmp_re.match(p.name)
            if m:
                killed = int(m.group(1))
                os.kill(killed, signal.SIGKILL)  # a Ray worker dies mid-shard
                break
        time.sleep(0.005)
    th.join(timeout=120)
    assert killed is not None, "no Ray worker was caught mid-shard"
    assert errors and isinstance(errors[0], DataError), errors
    assert len(_shards(out)) < FRAMES // SHARD

    s = dataset.simulate(out, FRAMES, seed=SEED, workers=2, config=LIGHT, shard_frames=SHARD, ray="", show_progress=False)
    assert s["generated"] + SHARD * s["resumed_shards"] == FRAMES
    assert _shards(out) == _shards(reference)  # nothing lost, nothing partial, nothing twice
    assert not list(out.glob(".*.tmp"))
    stamps = [f.stamp_ns for f in iter_frames(out)]
    assert len(stamps) == len(set(stamps)) == FRAMES
    assert _manifest(out)["shards"] == _manifest(reference)["shards"]


def test_a_node_with_other_physics_versions_writes_nothing(tmp_path):
    from sim.ray_runner import _shard_task

    out = tmp_path / "o"
    out.mkdir()
    with pytest.raises(DataError, match=r"has mujoco .* where the driver has 0\.0\.1, so its frames would differ"):
        _shard_task((0, SHARD), LIGHT.to_dict(), SEED, None, str(out), {"mujoco": "0.0.1"})
    assert list(out.iterdir()) == []


def test_ray_run_refuses_workers_whose_versions_differ_from_the_driver(tmp_path, local_ray, monkeypatch):
    from sim import ray_runner

    real = dataset.engines()
    monkeypatch.setattr(dataset, "engines", lambda: dict(real, mujoco="0.0.1"))  # the driver only: tasks run elsewhere
    submitted: list = []
    monkeypatch.setattr(ray_runner, "_shard_task", lambda *a, **k: submitted.append(a))  # must never be reached
    with pytest.raises(DataError, match=r"where the driver has 0\.0\.1.*; nothing was written$"):
        dataset.simulate(tmp_path / "o", FRAMES, seed=SEED, workers=2, config=LIGHT, shard_frames=SHARD,
                         show_progress=False, ray="")
    assert submitted == [] and not list((tmp_path / "o").glob("frames_*.mcap"))


def test_version_check_asks_every_live_node_once(local_ray):
    from sim import ray_runner

    ray_runner.check_nodes(local_ray, dataset.engines())  # agreeing versions: no error
    alive = [n for n in local_ray.nodes() if n.get("Alive")]
    assert len(alive) == 1

"""``--frames-range A:B``: array jobs into one folder give the dataset one run gives."""

from __future__ import annotations

import json

import pytest

from edge.errors import ConfigError
from sim import cli, dataset
from sim.generate import SimConfig

LIGHT = SimConfig.from_dict({"scene": {"n_objects": [0, 3]}})
FRAMES, SHARD = 8, 2


def _stats(out):
    m = json.loads((out / "manifest.json").read_text())
    return {k: {f: v for f, v in s.items() if f != "seconds"} for k, s in m["shards"].items()}


def test_array_jobs_then_final_run_equal_one_run(tmp_path):
    ref, arr = tmp_path / "ref", tmp_path / "arr"
    dataset.simulate(ref, FRAMES, seed=5, config=LIGHT, shard_frames=SHARD, show_progress=False)
    for a, b in ((4, 8), (0, 4)):  # in any order, each job alone
        s = dataset.simulate(arr, FRAMES, seed=5, config=LIGHT, shard_frames=SHARD, frames_range=(a, b),
                         show_progress=False)
        assert s["generated"] == b - a and s["frames_range"] == [a, b]
    assert (arr / "manifest.frames_00000000_00000004.json").exists()
    s = dataset.simulate(arr, FRAMES, seed=5, config=LIGHT, shard_frames=SHARD, show_progress=False)
    assert s["generated"] == 0 and s["object_pixel_fraction"] is not None
    names = sorted(p.name for p in ref.glob("frames_*.mcap"))
    assert names == sorted(p.name for p in arr.glob("frames_*.mcap"))
    assert all((ref / n).read_bytes() == (arr / n).read_bytes() for n in names)
    assert _stats(arr) == _stats(ref)


def test_a_job_leaves_other_jobs_temporary_files_alone(tmp_path):
    out = tmp_path / "o"
    out.mkdir()
    other = out / ".frames_00000006_00000008.mcap.4242.tmp"  # being written by another job
    mine = out / ".frames_00000000_00000002.mcap.4243.tmp"  # left by this job's killed predecessor
    other.write_bytes(b"x")
    mine.write_bytes(b"x")
    dataset.simulate(out, FRAMES, seed=5, config=LIGHT, shard_frames=SHARD, frames_range=(0, 2), show_progress=False)
    assert other.exists() and not mine.exists()


@pytest.mark.parametrize("text,msg", [("3:6", "shard boundary"), ("4:2", "START < STOP"), ("0:10", "START < STOP"),
                                      ("a:b", "START:STOP")])
def test_bad_ranges_are_one_line_errors(tmp_path, capsys, text, msg):
    rc = cli.main(["--out", str(tmp_path / "o"), "--frames", "8", "--shard-frames", "2", "--frames-range", text])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and msg in err[0], err


def test_range_job_refuses_another_length(tmp_path):
    out = tmp_path / "o"
    dataset.simulate(out, FRAMES, seed=5, config=LIGHT, shard_frames=SHARD, frames_range=(0, 2), show_progress=False)
    with pytest.raises(ConfigError, match="same `frames`"):
        dataset.simulate(out, 10, seed=5, config=LIGHT, shard_frames=SHARD, frames_range=(2, 4), show_progress=False)


def test_complete_shard_missing_from_the_manifest_gets_its_statistics_back(tmp_path):
    """A run killed between a shard's rename and its manifest update: the rerun reads the shard."""
    out = tmp_path / "o"
    dataset.simulate(out, FRAMES, seed=5, config=LIGHT, shard_frames=SHARD, show_progress=False)
    before = _stats(out)
    m = json.loads((out / "manifest.json").read_text())
    del m["shards"]["frames_00000002_00000004.mcap"]
    (out / "manifest.json").write_text(json.dumps(m))
    s = dataset.simulate(out, FRAMES, seed=5, config=LIGHT, shard_frames=SHARD, show_progress=False)
    assert s["generated"] == 0 and _stats(out) == before

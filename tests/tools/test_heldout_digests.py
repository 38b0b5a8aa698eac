"""tools/ablation/heldout.py's set digests: the same frames give the same digest, any change another."""

from __future__ import annotations

import json

import pytest
from toolmod import load_tool


@pytest.fixture(scope="module")
def ho():
    return load_tool("ablation/heldout.py")


def _set(folder, shards: dict[str, bytes]):
    folder.mkdir()
    for name, data in shards.items():
        (folder / name).write_bytes(data)
    (folder / "manifest.json").write_text(json.dumps({"seconds": 1.0}))
    return folder


def test_digest_covers_shard_bytes_and_names_but_not_the_manifest(ho, tmp_path):
    a = _set(tmp_path / "a", {"f_0_1.mcap": b"one", "f_1_2.mcap": b"two"})
    b = _set(tmp_path / "b", {"f_1_2.mcap": b"two", "f_0_1.mcap": b"one"})  # written in another order
    assert ho.set_digest(a) == ho.set_digest(b)
    (b / "manifest.json").write_text(json.dumps({"seconds": 2.0}))  # timings differ between runs
    assert ho.set_digest(a) == ho.set_digest(b)
    (b / "f_1_2.mcap").write_bytes(b"twO")
    assert ho.set_digest(a) != ho.set_digest(b)
    c = _set(tmp_path / "c", {"f_0_1.mcap": b"onetwo"})  # the same bytes cut into other shards
    assert ho.set_digest(c) != ho.set_digest(a)
    single = tmp_path / "one.mcap"
    single.write_bytes(b"one")
    assert len(ho.set_digest(single)) == 64


def test_report_names_the_sets_that_differ(ho, tmp_path):
    a = _set(tmp_path / "a", {"f.mcap": b"one"})
    b = _set(tmp_path / "b", {"f.mcap": b"two"})
    sets = [("A", str(a)), ("B", str(b)), ("C", str(tmp_path / "absent"))]
    rec = tmp_path / "digests.json"
    rec.write_text(json.dumps({"date": "2026-12-06", "cpu": "X", "sets": {str(a): ho.set_digest(a),
                                                                          str(b): ho.set_digest(b)}}))
    assert "2 of 3 present, all identical" in ho.digest_report(rec, sets)
    (b / "f.mcap").write_bytes(b"changed")
    line = ho.digest_report(rec, sets)
    assert "1 of 2 present differ" in line and line.endswith("by a few hundredths") and ": B;" in line
    assert "no recorded digests" in ho.digest_report(tmp_path / "none.json", sets)

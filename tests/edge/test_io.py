"""edge.io: the one atomic writer, the MCAP writer base, and the CLI rendering of parameter names."""

from __future__ import annotations

import argparse

import numpy as np
import pytest

from edge.cliutil import cli_message, flag_names
from edge.errors import DataError
from edge.io import TOPIC_DEPTH, FrameWriter, McapWriter, atomic_write, open_depth_stream, write_json_atomic


def test_atomic_write_keeps_the_old_file_when_the_block_fails(tmp_path):
    p = tmp_path / "a.json"
    write_json_atomic(p, {"v": 1})
    with pytest.raises(RuntimeError), atomic_write(p) as tmp:
        tmp.write_text("half")
        raise RuntimeError("power cut")
    assert p.read_text().strip().endswith("}") and '"v": 1' in p.read_text()
    assert [f.name for f in tmp_path.iterdir()] == ["a.json"]


def test_mcap_writer_appears_only_when_closed_and_never_after_an_error(tmp_path, scene):
    good, bad = tmp_path / "good.mcap", tmp_path / "bad.mcap"
    with FrameWriter(good) as w:
        d, lab = scene(0)
        w.write(1_000, d, lab)
        assert not good.exists() and w.tmp.exists()  # under a hidden temporary name until complete
    assert good.exists() and len(list(open_depth_stream(good))) == 1
    with pytest.raises(RuntimeError), McapWriter(bad) as w:
        w.add_image(w.image_channel(TOPIC_DEPTH), 1, 1, "f", np.zeros((2, 2), np.float32), "32FC1")
        raise RuntimeError("killed")
    assert sorted(f.name for f in tmp_path.iterdir()) == ["good.mcap"]
    with pytest.raises(DataError, match="is a directory"):
        McapWriter(tmp_path)
    with pytest.raises(DataError, match="compression"):
        McapWriter(tmp_path / "x.mcap", compression="gzip")


def test_cli_shows_parameters_as_the_parsers_flags():
    p = argparse.ArgumentParser()
    p.add_argument("--labels-topic")
    sub = p.add_subparsers(dest="cmd").add_parser("x")
    sub.add_argument("--shard-frames", type=int)
    flags = flag_names(p, aliases={"depth_topic": "--topic"})
    msg = "no labels; name it with `labels_topic` (or `depth_topic`), `shard_frames` >= 1, `other` stays"
    assert cli_message(msg, flags) == "no labels; name it with --labels-topic (or --topic), --shard-frames >= 1, `other` stays"

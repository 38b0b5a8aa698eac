"""Files say what wrote them: depthseg version and git commit in ONNX metadata and checkpoints."""

from __future__ import annotations

import re

import onnx
from exportgen import tiny_model

from edge.provenance import git_commit, package_version, provenance
from edge.train.checkpoint import read_checkpoint, save_checkpoint

COMMIT = re.compile(r"^([0-9a-f]{40}(-dirty)?|unknown)$")


def test_provenance_values():
    p = provenance()
    assert p == {"depthseg_version": package_version(), "git_commit": git_commit()}
    assert COMMIT.match(p["git_commit"]) and p["depthseg_version"]


def test_onnx_metadata_has_version_and_commit(plain_onnx, edge_onnx):
    for path in (plain_onnx, edge_onnx):
        props = {p.key: p.value for p in onnx.load(str(path)).metadata_props}
        assert props["depthseg_version"] == package_version()
        assert COMMIT.match(props["git_commit"]) and props["git_commit"] == git_commit()


def test_checkpoint_has_version_and_commit(tmp_path):
    model, meta = tiny_model(0)
    save_checkpoint(tmp_path / "m.pt", model, meta)
    assert read_checkpoint(tmp_path / "m.pt")["provenance"] == provenance()

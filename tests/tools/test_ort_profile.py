"""tools/ort_profile.py: onnxruntime's per-node profile of a model, largest first."""

from __future__ import annotations

import json

import pytest
from toolmod import load_tool


def test_the_profile_lists_the_nodes_largest_first_with_shares(tiny_onnx, capsys):
    tool = load_tool("ort_profile.py")
    rows = tool.profile(tiny_onnx, runs=3, threads=1)
    ops = {r["op"] for r in rows}
    assert {"MatMul", "ConvTranspose"} <= ops  # the folded head and the decoder, as onnxruntime runs them
    assert [r["median_us"] for r in rows] == sorted((r["median_us"] for r in rows), reverse=True)
    assert sum(r["share"] for r in rows) == pytest.approx(1.0)
    assert tool.main([str(tiny_onnx), "--runs", "2", "--threads", "1", "--json"]) == 0
    assert len(json.loads(capsys.readouterr().out)) == len(rows)


def test_a_missing_model_is_one_line(tmp_path, capsys):
    tool = load_tool("ort_profile.py")
    assert tool.main([str(tmp_path / "none.onnx")]) == 2
    err = capsys.readouterr().err
    assert "no such model file" in err and len(err.strip().splitlines()) == 1

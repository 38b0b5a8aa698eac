"""depthseg-export end to end: checkpoint -> checked ONNX, and one-line errors for bad input."""

from __future__ import annotations

import json

import onnx
import pytest
from exportgen import tiny_model

from edge.infer import Segmenter
from edge.meta import ModelMeta
from edge.train.checkpoint import save_checkpoint
from export.cli import main


def _one_line_error(capsys, rc: int, *needles: str) -> str:
    err = capsys.readouterr().err.strip()
    assert rc == 2, err
    assert len(err.splitlines()) == 1 and err.startswith("depthseg-export: error:") and "Traceback" not in err
    for n in needles:
        assert n in err
    return err


def test_checkpoint_to_single_channel_onnx(capsys, tmp_path):
    model, meta = tiny_model(3, in_channels=3)
    meta = meta.with_(threshold=0.37, threshold_policy="test: tuned", training={"epochs": 2, "loss": "bce"})
    ckpt = save_checkpoint(tmp_path / "tiny.pt", model, meta)
    out = tmp_path / "sub" / "tiny.onnx"
    rc = main(["--model", str(ckpt), "--single-channel", "--out", str(out), "--check-frames", "3", "--threads", "1", "--json"])
    captured = capsys.readouterr()
    assert rc == 0, captured.err
    rep = json.loads(captured.out)
    assert rep["out"] == str(out) and rep["precision"] == "fp32" and rep["graph"] == "logits" and rep["int8"] is None
    assert rep["check"]["ok"] and rep["check"]["max_abs_diff"] <= rep["check"]["tolerance"]
    assert rep["inputs"] == ["depth"] and rep["outputs"] == ["logits"] and rep["opset"] >= 17
    assert sorted(p.name for p in out.parent.iterdir()) == ["tiny.onnx"]
    props = {p.key: p.value for p in onnx.load(str(out)).metadata_props}
    got = ModelMeta.from_onnx_props(props)
    assert got == meta.with_(in_channels=1, params=got.params) and got.params < meta.params
    assert json.loads(props["training"]) == {"epochs": 2, "loss": "bce"}
    assert props["exported_from"] == "tiny" and props["single_channel"].startswith("True")
    seg = Segmenter(out, threads=1)
    assert seg.threshold == 0.37 and seg.meta.in_channels == 1 and seg.min_object_px == 6


def test_export_stores_the_speck_rule_asked_for(capsys, tmp_path):
    model, meta = tiny_model(3, in_channels=3)
    ckpt = save_checkpoint(tmp_path / "tiny.pt", model, meta)
    out = tmp_path / "tiny.onnx"
    rc = main(["--model", str(ckpt), "--out", str(out), "--check-frames", "2", "--threads", "1", "--min-object-px", "0"])
    assert rc == 0, capsys.readouterr().err
    seg = Segmenter(out, threads=1)
    assert seg.meta.min_object_px == 0 == seg.min_object_px and "under 0 px" in seg.props["postprocessing"]
    rc = main(["--model", str(ckpt), "--out", str(tmp_path / "x.onnx"), "--min-object-px", "-2"])
    _one_line_error(capsys, rc, "min_object_px")
    assert not (tmp_path / "x.onnx").exists()


def test_export_stores_the_height_rule_asked_for(capsys, tmp_path):
    model, meta = tiny_model(3, in_channels=3)
    ckpt = save_checkpoint(tmp_path / "tiny.pt", model, meta)
    out = tmp_path / "tiny.onnx"
    rc = main(["--model", str(ckpt), "--out", str(out), "--check-frames", "2", "--threads", "1", "--min-height-mm", "10"])
    assert rc == 0, capsys.readouterr().err
    seg = Segmenter(out, threads=1)
    assert seg.meta.min_height_m == 0.01 == seg.min_height_m and "under 10 mm" in seg.props["postprocessing"]
    assert Segmenter(out, threads=1, min_height_m=0.0).min_height_m == 0.0  # a run may switch it off


def test_missing_checkpoint_is_one_line(capsys, tmp_path):
    rc = main(["--model", str(tmp_path / "nope.pt"), "--out", str(tmp_path / "x.onnx")])
    _one_line_error(capsys, rc, "nope.pt", "no such checkpoint")
    assert not (tmp_path / "x.onnx").exists()


def test_corrupt_checkpoint_is_one_line(capsys, tmp_path):
    bad = tmp_path / "bad.pt"
    bad.write_bytes(b"\x00not a checkpoint" * 10)
    rc = main(["--model", str(bad), "--out", str(tmp_path / "x.onnx")])
    _one_line_error(capsys, rc, "bad.pt", "not a readable depthseg checkpoint")


@pytest.mark.parametrize(
    "argv, needle",
    [
        (["--encoder", "vgg16"], "need --random-init"),
        (["--random-init", "--encoder", "vgg99"], "unknown encoder 'vgg99'"),
        (["--random-init", "--model", "x.pt"], "drop --model"),
        (["--random-init", "--check-frames", "0"], "--check-frames must be >= 1"),
        (["--random-init", "--encoder", "vgg11", "--width", "0.125", "--data", "/nonexistent/sim"], "/nonexistent/sim"),
    ],
)
def test_bad_options_are_one_line(capsys, tmp_path, argv, needle):
    rc = main(argv + ["--out", str(tmp_path / "x.onnx")])
    _one_line_error(capsys, rc, needle)
    assert not (tmp_path / "x.onnx").exists()

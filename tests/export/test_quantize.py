"""int8: QDQ per-channel quantisation, what really runs in int8, IoU report and refusal."""

from __future__ import annotations

import json

import numpy as np
import onnx
import pytest

from edge.errors import DataError
from edge.infer import Segmenter
from edge.meta import ModelMeta
from edge.sampleframes import FrameSample, synthetic_frames
from export import quantize


@pytest.fixture(scope="module")
def fp32_and_int8(plain_onnx, tiny1, tmp_path_factory):
    q = quantize.quantize_int8(plain_onnx, tmp_path_factory.mktemp("int8") / "int8.onnx", synthetic_frames(8, 0))
    return plain_onnx, q, tiny1[1]


def test_int8_file_keeps_metadata_and_says_int8(fp32_and_int8):
    fp32, q, meta = fp32_and_int8
    props = {p.key: p.value for p in onnx.load(str(q)).metadata_props}
    assert ModelMeta.from_onnx_props(props) == meta
    assert props["precision"] == "int8" and "QDQ" in props["quantization"] and "per_channel=True" in props["quantization"]
    assert q.stat().st_size < 0.5 * fp32.stat().st_size
    assert Segmenter(q, threads=1).precision == "int8"


def test_encoder_convs_run_int8_and_deconvs_stay_fp32(fp32_and_int8):
    _fp32, q, _meta = fp32_and_int8
    layers = quantize.int8_layers(q)
    assert layers["int8"].get("QLinearConv", 0) == 8  # the 8 encoder convs
    assert layers["fp32"].get("MatMul", 0) >= 1  # the folded head (export.fold) stays float32
    assert layers["fp32"].get("ConvTranspose", 0) == 5  # no int8 ConvTranspose on onnxruntime's CPU provider
    assert layers["qdq"]["DequantizeLinear"] > 0


def test_iou_report_compares_both_files_on_labelled_frames(fp32_and_int8):
    fp32, q, _meta = fp32_and_int8
    rep = quantize.iou_report(fp32, q, synthetic_frames(6, 50), threads=1)
    assert rep.frames == 6 and 0 <= rep.iou_int8 <= 100 and 0 <= rep.iou_fp32 <= 100
    assert rep.drop == pytest.approx(rep.iou_fp32 - rep.iou_int8)
    assert rep.agreement_iou > 90.0  # int8 mostly agrees with fp32, but is not the same file
    assert rep.max_abs_prob_diff > 0.0
    assert rep.layers["int8"]["QLinearConv"] == 8


def test_iou_report_needs_labels(fp32_and_int8):
    fp32, q, _meta = fp32_and_int8
    unlabelled = FrameSample(depth=synthetic_frames(2).depth, label=[None, None], source="unlabelled")
    with pytest.raises(DataError, match="needs labelled frames"):
        quantize.iou_report(fp32, q, unlabelled)


def test_pooled_iou_counts_valid_pixels_only():
    m = np.array([[1, 1, 0, 255]], np.uint8)
    lab = np.array([[1, 0, 0, 1]], np.uint8)
    v = np.array([[True, True, True, False]])
    assert quantize.pooled_iou([m], [lab], [v]) == pytest.approx(1 / 2)
    assert quantize.pooled_iou([np.zeros_like(m)], [np.zeros_like(lab)], [v]) == 1.0


@pytest.mark.slow
def test_cli_refuses_an_int8_model_that_loses_iou_unless_forced(monkeypatch, capsys, tmp_path):
    from export.cli import main

    real = quantize.iou_report

    def lossy(*a, **k):  # the real report, with the int8 IoU 2 points lower
        rep = real(*a, **k)
        return quantize.Int8Report(**{**{f: getattr(rep, f) for f in rep.__dataclass_fields__}, "iou_int8": rep.iou_fp32 - 2.0})

    monkeypatch.setattr(quantize, "iou_report", lossy)
    out = tmp_path / "q.onnx"
    args = ["--random-init", "--encoder", "vgg11_bn", "--width", "0.125", "--single-channel", "--int8", "--out", str(out),
            "--check-frames", "2", "--calib-frames", "4", "--val-frames", "3", "--threads", "1"]
    assert main(args) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "loses 2.00 IoU points" in err and "--force" in err
    assert not out.exists() and list(tmp_path.iterdir()) == []  # nothing half-written
    assert main(args + ["--force", "--json"]) == 0
    rep = json.loads(capsys.readouterr().out)
    assert rep["int8"]["forced"] and rep["int8"]["drop"] == pytest.approx(2.0) and rep["precision"] == "int8"
    props = {p.key: p.value for p in onnx.load(str(out)).metadata_props}
    assert json.loads(props["int8_check"])["forced"] is True

"""Evaluation end to end: predictors, streaming scores, figures, baseline and the CLI."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from replaygen import scene as shared_scene

from edge import defaults
from edge.errors import ConfigError, DataError, ModelError
from edge.eval_cli import main as eval_main
from edge.evaluate import COLORS, evaluate, render_figure
from edge.io import Frame, FrameWriter, iter_frames
from edge.meta import ModelMeta, fov_intrinsics
from edge.metrics import MetricAccumulator, object_mask, predict_mask
from edge.predict import Predictor, load_predictor

H, W = 64, 96
TINY = ModelMeta(encoder="vgg11", width=0.125, batch_norm=True, in_channels=1, threshold=0.5)  # the Oracle's


def scene(i: int) -> tuple[np.ndarray, np.ndarray]:
    """The shared scene (`replaygen.scene`) at 64 x 96: frame 0 has no object (a frame without
    objects scores recall 1) and odd frames mark invalid pixels NaN instead of 0 (both encodings)."""
    depth, label = shared_scene(i, H, W, box=i > 0)
    if i % 2:
        depth[depth == 0] = np.nan
    return depth, label


def write_frames(path: Path, n: int = 4, labels: bool = True) -> Path:
    k = fov_intrinsics(W, H, 62.0, 45.0)
    with FrameWriter(path) as w:
        for i in range(n):
            d, lab = scene(i)
            w.write(i * 100_000_000, d, lab if labels else None, intrinsics=k)
    return path


@pytest.fixture(scope="module")
def tiny_ckpt(tiny_pt, tmp_path_factory) -> Path:
    """The shared ``tiny_pt`` with threshold 0.4 stored: these tests show the model's own threshold is used, not 0.5."""
    from edge.train.threshold_store import store_threshold

    return store_threshold(tiny_pt, 0.4, "tests", out=tmp_path_factory.mktemp("model") / "tiny.pt")[0]


@pytest.fixture(scope="module")
def data(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("data")
    write_frames(d / "a.mcap", 3)
    write_frames(d / "b.mcap", 2)
    return d


def mem_frames(n: int = 4) -> list[Frame]:
    return [Frame(depth=d, stamp_ns=i, label=lab) for i, (d, lab) in enumerate(scene(i) for i in range(n))]


class Oracle(Predictor):
    """Logits (+/-5) from the labels of the frame whose depth it is given; optionally inverted."""

    def __init__(self, frames: list[Frame], invert: bool = False):
        self.meta = TINY
        self.name = "oracle"
        self.invert = invert
        self.labels = {fr.depth.tobytes(): fr.label for fr in frames}

    def logits(self, depth):
        s = np.where(self.labels[depth.tobytes()] > 0, 5.0, -5.0).astype(np.float32)
        return -s if self.invert else s


def test_perfect_and_inverted_predictions():
    frames = mem_frames()
    r = evaluate(Oracle(frames), iter(frames))
    assert r.frames == 4
    assert (r.metrics.pixel_accuracy, r.metrics.iou, r.metrics.precision, r.metrics.recall) == (1, 1, 1, 1)
    r = evaluate(Oracle(frames, invert=True), iter(frames))
    assert r.metrics.pixel_accuracy == 0.0 and r.metrics.iou == 0.0 and r.metrics.pooled_iou == 0.0
    # frame 0 has no objects: everything predicted object -> precision 0, recall 1
    assert r.metrics.recall == pytest.approx(1 / 4)
    assert r.metrics.precision == 0.0


def test_invalid_pixels_do_not_count():
    frames = mem_frames(2)
    for fr in frames:
        fr.label = fr.label.copy()
        fr.label[~(np.isfinite(fr.depth) & (fr.depth > 0))] = 1  # labels on invalid pixels: ignored
    oracle = Oracle(mem_frames(2))
    r = evaluate(oracle, iter(frames))
    assert r.metrics.iou == 1.0 and r.metrics.pixel_accuracy == 1.0


def test_scores_come_from_the_model(tiny_ckpt, data):
    p = load_predictor(tiny_ckpt, threads=1)
    assert p.meta.threshold == 0.4 and p.name == str(tiny_ckpt)
    r = evaluate(p, iter_frames(data))
    assert r.frames == 5 and r.threshold == 0.4 and r.min_object_px == p.meta.min_object_px == 6
    r0 = evaluate(p, iter_frames(data), min_object_px=0)  # the speck rule off: the bare threshold rule
    acc, acc0 = MetricAccumulator(), MetricAccumulator()
    for fr in iter_frames(data):
        logits = p.logits(fr.depth)
        assert logits.shape == (H, W) and logits.dtype == np.float32
        valid = np.isfinite(fr.depth) & (fr.depth > 0)
        acc.add(object_mask(logits, valid, 0.4, 6), fr.label, valid)
        acc0.add(predict_mask(logits, 0.4), fr.label, valid)
    assert r.metrics == acc.summary() and r0.metrics == acc0.summary()
    r2 = evaluate(p, iter_frames(data), threshold=0.9, limit=2)
    assert r2.frames == 2 and r2.threshold == 0.9


def test_baseline_and_figures(tiny_ckpt, data, tmp_path):
    p = load_predictor(tiny_ckpt, threads=1)
    figs = tmp_path / "figs"
    r = evaluate(p, iter_frames(data), baseline=True, figures_dir=figs, max_figures=2)
    assert r.baseline is not None and r.baseline.frames == 5
    assert r.baseline.iou > 0.9  # boxes 2-4 cm above a flat floor
    assert [f.name for f in r.figures] == ["frame_000000.png", "frame_000001.png"]
    assert sorted(f.name for f in figs.iterdir()) == ["frame_000000.png", "frame_000001.png"]
    r = evaluate(p, iter_frames(data), figures_dir=figs, max_figures=1, figure_pick="worst")
    assert len(r.figures) == 1 and r.figures[0].name.startswith("worst_")
    d = r.to_dict()
    assert d["figures"] == [str(r.figures[0])]


def test_figure_colours():
    import cv2

    depth, label = scene(1)
    pred = np.zeros_like(label, bool)
    pred[0:5, 40:50] = True  # false object
    img = render_figure(depth, label, pred, scale=1)
    assert img.dtype == np.uint8 and img.ndim == 3
    colours = {tuple(int(v) for v in c) for c in img.reshape(-1, 3)}
    for name in ("correct background", "missed object", "false object", "invalid", "correct object"):
        assert COLORS[name] in colours, name
    ok, _ = cv2.imencode(".png", img)
    assert ok


def test_unlabelled_frames_are_counted_and_none_is_an_error(tiny_ckpt, tmp_path):
    p = load_predictor(tiny_ckpt, threads=1)
    f = write_frames(tmp_path / "nolab.mcap", 2, labels=False)
    with pytest.raises(DataError, match="no labelled frames"):
        evaluate(p, iter_frames(f))


def test_bad_arguments(tiny_ckpt, data):
    p = load_predictor(tiny_ckpt, threads=1)
    with pytest.raises(ConfigError):
        evaluate(p, iter_frames(data), threshold=1.0)
    with pytest.raises(ConfigError):
        evaluate(p, iter_frames(data), figure_pick="best")
    with pytest.raises(ConfigError):
        evaluate(p, iter_frames(data), limit=0)


def test_load_predictor_errors_and_default(tmp_path, monkeypatch, tiny_ckpt):
    with pytest.raises(ModelError, match="no such model"):
        load_predictor(tmp_path / "missing.pt")
    (tmp_path / "m.bin").write_bytes(b"x")
    with pytest.raises(ModelError, match="unknown model type"):
        load_predictor(tmp_path / "m.bin")
    (tmp_path / "bad.pt").write_bytes(b"not a checkpoint")
    with pytest.raises(ModelError, match="not a readable depthseg checkpoint"):
        load_predictor(tmp_path / "bad.pt")
    monkeypatch.setattr(defaults, "DEFAULT_CHECKPOINT", tmp_path / "none.pt")
    monkeypatch.setattr(defaults, "DEFAULT_ONNX", tmp_path / "none.onnx")
    with pytest.raises(ModelError, match="default model is missing"):
        load_predictor(None)
    monkeypatch.setattr(defaults, "DEFAULT_CHECKPOINT", tiny_ckpt)
    assert load_predictor(None).name == str(tiny_ckpt)


# ------------------------------------------------------------------------------------------ CLI


def test_cli_json_keys(tiny_ckpt, data, capsys):
    assert eval_main(["--model", str(tiny_ckpt), "--data", str(data), "--json", "--threads", "1"]) == 0
    out = json.loads(capsys.readouterr().out)
    for k in ("frames", "pixel_accuracy", "iou", "precision", "recall", "threshold", "pooled_iou"):
        assert k in out, k
    assert out["frames"] == 5 and out["threshold"] == 0.4
    for k in ("pixel_accuracy", "iou", "precision", "recall", "pooled_iou"):
        assert 0.0 <= out[k] <= 1.0
    assert "baseline" not in out
    bd = out["breakdown"]  # always there, default 2 px band; the void-band score only on request
    assert bd["boundary_px"] == 2 and "ignore_boundary" not in out
    assert bd["tp"] == pytest.approx(out["pooled_iou"])


BREAKDOWN_KEYS = ("tp", "fp_boundary", "fp_far", "fn_boundary", "fn_far")


def test_cli_breakdown_and_ignore_boundary_for_model_and_baseline(tiny_ckpt, data, capsys):
    rc = eval_main(["--model", str(tiny_ckpt), "--data", str(data), "--json", "--baseline", "--threads", "1",
                    "--boundary-px", "1", "--ignore-boundary", "2"])
    assert rc == 0
    out = json.loads(capsys.readouterr().out)
    for d in (out, out["baseline"]):
        bd = d["breakdown"]
        assert bd["boundary_px"] == 1
        assert all(0.0 <= bd[k] <= 1.0 for k in BREAKDOWN_KEYS)
        assert sum(bd[k] for k in BREAKDOWN_KEYS) == pytest.approx(1.0)
        assert bd["tp"] == pytest.approx(d["pooled_iou"])
        c = bd["counts"]
        assert c["tp"] == d["pooled_counts"]["tp"] and c["fp_boundary"] + c["fp_far"] == d["pooled_counts"]["fp"]
        ig = d["ignore_boundary"]
        assert ig["px"] == 2 and ig["frames"] == 5
        assert all(0.0 <= ig[k] <= 1.0 for k in ("iou", "precision", "recall", "pooled_iou"))
        assert ig["pooled_counts"]["tp"] < d["pooled_counts"]["tp"]  # the void band took pixels away
    # the 2-4 cm boxes are easy for the baseline: what it gets wrong is on the outlines
    b = out["baseline"]["breakdown"]
    assert b["fp_boundary"] + b["fn_boundary"] >= b["fp_far"] + b["fn_far"]
    rc = eval_main(["--model", str(tiny_ckpt), "--data", str(data / "a.mcap"), "--baseline", "--threads", "1",
                    "--ignore-boundary", "1"])
    assert rc == 0
    table = capsys.readouterr().out
    assert "Where the errors are" in table and "within 2 px" in table
    for col in ("FP bound.", "FP far", "FN bound.", "FN far"):
        assert col in table
    assert "EXTRA score, ignoring a 1 px void band" in table and "[void band]" in table
    assert table.count("RANSAC plane + 8 mm") == 3  # plain, breakdown and void-band rows
    assert eval_main(["--model", str(tiny_ckpt), "--data", str(data), "--boundary-px", "-1"]) == 2
    assert "boundary band width" in capsys.readouterr().err


def test_cli_table_baseline_and_figures(tiny_ckpt, data, tmp_path, capsys):
    figs = tmp_path / "figs"
    rc = eval_main(["--model", str(tiny_ckpt), "--data", str(data / "a.mcap"), "--baseline", "--figures", str(figs),
                    "--max-figures", "2", "--threshold", "0.6", "--threads", "1"])
    assert rc == 0
    out = capsys.readouterr().out
    assert "Pixel acc." in out and "Pooled IoU" in out and "RANSAC plane + 8 mm" in out
    assert "3 frames, threshold 0.6" in out
    assert len(list(figs.glob("*.png"))) == 2
    rc = eval_main(["--model", str(tiny_ckpt), "--data", str(data), "--baseline", "--json", "--limit", "2"])
    assert rc == 0
    out = json.loads(capsys.readouterr().out)
    assert out["frames"] == 2
    b = out["baseline"]
    for k in ("frames", "pixel_accuracy", "iou", "precision", "recall", "threshold", "pooled_iou"):
        assert k in b, k
    assert b["frames"] == 2 and b["threshold"] == 0.008 and b["iou"] > 0.9


def test_cli_no_labels_is_one_line_error(tiny_ckpt, tmp_path, capsys):
    f = write_frames(tmp_path / "nolab.mcap", 2, labels=False)
    rc = eval_main(["--model", str(tiny_ckpt), "--data", str(f)])
    err = capsys.readouterr().err
    assert rc != 0
    assert len(err.strip().splitlines()) == 1
    assert "no labels found" in err and "/pico_flexx/image_depth" in err and "Traceback" not in err


def test_cli_bad_inputs(tiny_ckpt, tmp_path, capsys):
    rc = eval_main(["--model", str(tiny_ckpt), "--data", str(tmp_path / "nothing")])
    assert rc == 2 and "no such file" in capsys.readouterr().err
    (tmp_path / "junk.mcap").write_bytes(b"garbage")
    rc = eval_main(["--model", str(tiny_ckpt), "--data", str(tmp_path / "junk.mcap")])
    err = capsys.readouterr().err
    assert rc == 2 and "not an MCAP file" in err and len(err.strip().splitlines()) == 1
    data = write_frames(tmp_path / "ok.mcap", 1)
    rc = eval_main(["--model", str(tmp_path / "missing.onnx"), "--data", str(data)])
    assert rc == 2 and "no such model file" in capsys.readouterr().err


def write_custom(path: Path, depth_topic: str, label_topic: str, n: int = 3) -> Path:
    """A user's own ROS 2 recording: other topic names, no camera_info."""
    from mcap.writer import Writer

    from edge import rosmsg

    with open(path, "wb") as fh:
        w = Writer(fh)
        w.start(profile="ros2", library="test")
        sid = w.register_schema(rosmsg.IMAGE_TYPE, "ros2msg", rosmsg.IMAGE_MSGDEF.encode())
        dch = w.register_channel(depth_topic, "cdr", sid)
        lch = w.register_channel(label_topic, "cdr", sid)
        for i in range(n):
            d, lab = scene(i)
            t = (i + 1) * 50_000_000
            w.add_message(dch, log_time=t, publish_time=t, data=rosmsg.encode_image(t, "cam", d, "32FC1"))
            w.add_message(lch, log_time=t, publish_time=t, data=rosmsg.encode_image(t, "cam", lab * 255, "mono8"))
        w.finish()
    return path


def test_cli_users_recording_auto_and_named_topics(tiny_ckpt, tmp_path, capsys):
    f = write_custom(tmp_path / "rec.mcap", "/camera/depth/image_raw", "/camera/labels")
    assert eval_main(["--model", str(tiny_ckpt), "--data", str(f), "--json", "--baseline"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["frames"] == 3 and out["baseline"]["iou"] > 0.9
    g = write_custom(tmp_path / "rec2.mcap", "/camera/depth/image_raw", "/camera/object_mask")
    rc = eval_main(["--model", str(tiny_ckpt), "--data", str(g), "--json"])
    err = capsys.readouterr().err
    assert rc == 2 and "/camera/object_mask" in err and "--labels-topic" in err
    rc = eval_main(["--model", str(tiny_ckpt), "--data", str(g), "--json", "--labels-topic", "/camera/object_mask",
                    "--depth-topic", "/camera/depth/image_raw"])
    assert rc == 0 and json.loads(capsys.readouterr().out)["frames"] == 3


def test_onnx_model_scores_like_its_checkpoint(tiny_pt, tiny_onnx, data, capsys):
    """The same weights as .pt (torch) and .onnx (onnxruntime, edge path) give the same table."""
    onnx_path = tiny_onnx
    a, b = load_predictor(onnx_path, threads=1), load_predictor(tiny_pt, threads=1)
    assert type(a).__name__ == "Segmenter" and type(b).__name__ == "TorchPredictor"
    for k in ("encoder", "width", "threshold", "sensor", "standardize", "cues"):
        assert getattr(a.meta, k) == getattr(b.meta, k), k
    depth, _ = scene(2)
    assert np.abs(a.logits(depth) - b.logits(depth)).max() < 1e-4
    rc = eval_main(["--model", str(onnx_path), "--data", str(data), "--json", "--threads", "1"])
    assert rc == 0
    got = json.loads(capsys.readouterr().out)
    ref = evaluate(b, iter_frames(data)).to_dict()
    for k in ("frames", "threshold", "pixel_accuracy", "iou", "precision", "recall", "pooled_iou"):
        assert got[k] == pytest.approx(ref[k], abs=1e-3), k


ROOT = Path(__file__).resolve().parents[2]  # the repository
SHARED = ROOT.parent / "shared"


def test_eval_blensor_tool(tiny_ckpt, capsys):
    """tools/eval_blensor.py scores the 9 BlenSor scans with objects (the paper's own simulator)."""
    blensor = SHARED / "data" / "blensor"
    if not (blensor / "scan_1.npy").exists():
        pytest.skip(f"BlenSor scans not found at {blensor}")
    from toolmod import load_tool

    mod = load_tool("eval_blensor.py")
    assert mod.main(["--model", str(tiny_ckpt), "--data", str(blensor), "--json", "--baseline", "--threads", "1"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["frames"] == 9 and out["scans"] == [f"scan_{i}.npy" for i in range(1, 10)]
    assert out["baseline"]["frames"] == 9
    assert 0.5 < out["baseline"]["iou"] <= 1.0  # the classical baseline finds most objects on BlenSor
    assert out["skipped_frames"] == 0 and out["unlabelled_frames"] == 0
    for d in (out, out["baseline"]):
        assert d["breakdown"]["boundary_px"] == 2
        assert sum(d["breakdown"][k] for k in BREAKDOWN_KEYS) == pytest.approx(1.0)

"""``depthseg-replay`` end to end: real onnxruntime models, exit codes, one-line errors, no torch."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest
from mcap.reader import make_reader
from replaygen import SHARED, T0, scene, write_kind, write_ros2

from edge.io import FrameWriter
from replay.cli import main

REPO = __import__("pathlib").Path(__file__).resolve().parents[2]
JSON_KEYS = {"frames", "fps", "p50_ms"}
LABEL_KEYS = {"iou", "precision", "recall", "pixel_accuracy"}


def run_cli(capsys, *args):
    rc = main([str(a) for a in args])
    cap = capsys.readouterr()
    return rc, cap.out, cap.err


def assert_one_line_error(rc, err, *needles):
    assert rc == 2
    lines = [ln for ln in err.splitlines() if ln.startswith("depthseg-replay: error:")]
    assert len(lines) == 1, err
    assert "Traceback" not in err
    for n in needles:
        assert n in lines[0], lines[0]


@pytest.mark.parametrize("kind", ["ros32_zero", "fox_proto"])
def test_json_summary_with_labels(kind, linear_onnx, tmp_path, capsys):
    rec = write_kind(kind, tmp_path / "r.mcap", n=5)
    rc, out, err = run_cli(capsys, rec.path, "--model", linear_onnx, "--json", "--threads", "1")
    assert rc == 0, err
    d = json.loads(out)
    assert JSON_KEYS | LABEL_KEYS <= set(d)
    assert d["frames"] == 5 and d["fps"] > 0 and d["p50_ms"] > 0
    assert 0.0 <= d["iou"] <= 1.0
    assert f"depth topic {rec.topic}" in err


def test_text_summary_and_output_file(linear_onnx, tmp_path, capsys):
    rec = write_kind("ros16", tmp_path / "r.mcap", n=4)
    out = tmp_path / "seg.mcap"
    rc, text, err = run_cli(capsys, rec.path, "--model", linear_onnx, "--out", out, "--rate", "20")
    assert rc == 0, err
    for needle in ("frames: 4", "frames/s:", "latency ms: p50", "p90", "p99", "iou", "precision", "recall",
                   "pixel_accuracy", f"wrote {out}", "paced at 20x"):
        assert needle in text, needle
    with open(out, "rb") as fh:
        topics = {c.topic for c in make_reader(fh).get_summary().channels.values()}
    assert {"/depthseg/mask", "/depthseg/overlay", rec.topic, "/pico_flexx/camera_info"} <= topics
    assert "camera_info /pico_flexx/camera_info: 32x24" in err
    assert "frames are 32x24, the model was trained on 224x171" in err


def test_threshold_flag_changes_the_result(linear_onnx, tmp_path, capsys):
    rec = write_kind("ros32_zero", tmp_path / "r.mcap", n=3)
    res = {}
    for t in ("0.01", "0.99"):
        rc, out, _ = run_cli(capsys, rec.path, "--model", linear_onnx, "--json", "--threshold", t)
        assert rc == 0
        res[t] = json.loads(out)
    assert res["0.01"]["threshold"] == 0.01 and res["0.99"]["threshold"] == 0.99
    assert res["0.01"]["object_fraction"] >= res["0.99"]["object_fraction"]


def test_damaged_input_output_written_error_and_exit_2(linear_onnx, tmp_path, capsys):
    rec = write_kind("ros32_nan", tmp_path / "r.mcap", n=8)
    data = rec.path.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: len(data) // 2])
    out = tmp_path / "seg.mcap"
    rc, text, err = run_cli(capsys, cut, "--model", linear_onnx, "--out", out, "--json")
    assert_one_line_error(rc, err, "damaged at byte", "truncated")
    d = json.loads(text)  # the summary of what was replayed is still printed
    assert 0 < d["frames"] < 8 and "damaged" in d["error"]
    with open(out, "rb") as fh:  # and the output is a complete MCAP up to the damage
        r = make_reader(fh)
        n_masks = sum(1 for _ in r.iter_messages(topics=["/depthseg/mask"]))
    assert n_masks == d["frames"]


@pytest.mark.parametrize(
    "make, args, needles",
    [
        (lambda p: p.write_bytes(b""), [], ["empty file"]),
        (lambda p: p.mkdir(), [], ["is a directory"]),
        (lambda p: None, [], ["no such file"]),
        (lambda p: p.write_text("x" * 100), [], ["not an MCAP file"]),
        (lambda p: write_ros2(p, n=2), ["--rate", "0"], ["--rate must be a number from 0.001 to 1000"]),
        (lambda p: write_ros2(p, n=2), ["--threshold", "1.5"], ["threshold must lie in (0, 1)"]),
        (lambda p: write_ros2(p, n=2), ["--threads", "0"], ["--threads must be >= 1"]),
        (lambda p: write_ros2(p, n=2), ["--topic", "/nope"], ["no depth topic '/nope'", "/pico_flexx/image_depth"]),
        (lambda p: write_ros2(p, n=2, corrupt_frame=1), [], ["malformed", "height x step"]),
    ],
    ids=["empty", "dir", "missing", "text", "rate", "threshold", "threads", "topic", "malformed"],
)
def test_bad_inputs_are_one_line_errors(make, args, needles, linear_onnx, tmp_path, capsys):
    p = tmp_path / "in.mcap"
    make(p)
    rc, _, err = run_cli(capsys, p, "--model", linear_onnx, *args)
    assert_one_line_error(rc, err, *needles)


def test_bad_models_are_one_line_errors(tmp_path, capsys):
    rec = write_ros2(tmp_path / "in.mcap", n=2)
    (tmp_path / "m.pt").write_bytes(b"x")
    rc, _, err = run_cli(capsys, rec.path, "--model", tmp_path / "m.pt")
    assert_one_line_error(rc, err, "replay runs exported ONNX models", "depthseg-export")
    rc, _, err = run_cli(capsys, rec.path, "--model", tmp_path / "missing.onnx")
    assert_one_line_error(rc, err, "no such model file")
    (tmp_path / "junk.onnx").write_bytes(b"junk")
    rc, _, err = run_cli(capsys, rec.path, "--model", tmp_path / "junk.onnx")
    assert_one_line_error(rc, err, "not a readable ONNX model")
    rc, _, err = run_cli(capsys, rec.path, "--model", tmp_path / "junk.onnx", "--out", rec.path)
    assert_one_line_error(rc, err, "would overwrite the input")


MCAP_DIR = SHARED / "data" / "mcap"


@pytest.mark.skipif(not MCAP_DIR.is_dir(), reason=f"{MCAP_DIR} not present (../shared beside the repo)")
def test_shared_foreign_bags(linear_onnx, capsys):
    rc, _, err = run_cli(capsys, MCAP_DIR / "rosbag2_wrong_rmw.mcap", "--model", linear_onnx)
    assert_one_line_error(rc, err, "'wrong_format' cannot be decoded")
    rc, _, err = run_cli(capsys, MCAP_DIR / "rosbags_test_bag.mcap", "--model", linear_onnx)
    assert_one_line_error(rc, err, "no depth image topic", "/test/sensor_msgs/image (sensor_msgs/msg/Image, rgb8")
    rc, _, err = run_cli(capsys, MCAP_DIR / "rosbags_test_bag.mcap", "--model", linear_onnx,
                         "--topic", "/test/sensor_msgs/image")
    assert_one_line_error(rc, err, "data has 30 bytes but height x step = 480 x 1920", "malformed")


def test_help_explains():
    r = subprocess.run([sys.executable, "-m", "replay.cli", "--help"], capture_output=True, text=True, cwd=REPO)
    assert r.returncode == 0
    for needle in ("--topic", "--labels-topic", "--out", "--rate", "--threshold", "--json", "/depthseg/mask",
                   "255 unknown", "multiples of 32"):
        assert needle in r.stdout, needle


def test_exported_fcn_replays_like_depthseg_eval(tmp_path, capsys, tiny_onnx):
    """The shared tiny FCN-8s exported by export.onnx_export: replay and evaluation agree."""
    from edge.evaluate import evaluate
    from edge.io import iter_frames
    from edge.predict import load_predictor

    model_path = tiny_onnx
    rec = tmp_path / "sim.mcap"
    with FrameWriter(rec) as w:
        for i in range(4):
            d, lab = scene(i, 171, 224)
            w.write(T0 + i * 25_000_000, d, label=lab, intrinsics=(200.0, 200.0, 111.5, 85.0))
    rc, out, err = run_cli(capsys, rec, "--model", model_path, "--json", "--threads", "1")
    assert rc == 0, err
    got = json.loads(out)
    assert got["frames"] == 4 and got["sizes"] == ["224x171"]
    ref = evaluate(load_predictor(model_path, threads=1), iter_frames(rec)).to_dict()
    for k in ("iou", "precision", "recall", "pixel_accuracy"):
        assert got[k] == pytest.approx(ref[k], abs=1e-3), k
    assert np.isfinite(got["p99_ms"])


def test_min_height_flag_makes_low_object_pixels_table(tmp_path, capsys):
    # a model that calls every valid pixel object, the table too: the height rule
    # (edge.postprocess.remove_low_parts) must leave the box, which reaches over the line
    from onnxgen import linear_model

    model = linear_model(tmp_path / "all.onnx", bias=100.0)
    rec = write_kind("ros32_zero", tmp_path / "r.mcap", n=3)
    res = {}
    for mm in ("0", "10"):
        rc, out, err = run_cli(capsys, rec.path, "--model", model, "--json", "--min-height-mm", mm)
        assert rc == 0, err
        res[mm] = json.loads(out)
    assert res["0"]["object_fraction"] == 1.0 and res["0"]["min_height_m"] == 0.0
    assert res["10"]["min_height_m"] == 0.01 and 0.0 < res["10"]["object_fraction"] < 0.2
    assert res["10"]["iou"] > 0.9 > res["0"]["iou"]
    with pytest.raises(SystemExit) as e:  # argparse's one-line usage error
        run_cli(capsys, rec.path, "--model", model, "--min-height-mm", "nan")
    err = capsys.readouterr().err
    assert e.value.code == 2 and "--min-height-mm" in err and "Traceback" not in err

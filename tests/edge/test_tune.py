"""Threshold tuning: the sweep's answers, objective parsing, errors, and the stored threshold's journey.

The sweep is checked against `edge.metrics` (an independent implementation of the same scores)
on synthetic logits, and against hand-built frames whose best threshold is known. The storage
tests run the real CLI on tiny synthetic MCAP scenes with a random-init tiny model.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from tinymodel import TINY_H as H
from tinymodel import TINY_SENSOR as SMALL
from tinymodel import TINY_W as W

from edge.errors import ConfigError, DataError, ModelError, ThresholdError
from edge.io import FrameWriter
from edge.meta import ModelMeta
from edge.metrics import MetricAccumulator
from edge.tune import (
    LOGIT_LIMIT,
    ThresholdSweep,
    choose_threshold,
    heldout_assigner,
    logit_grid,
    parse_objective,
    sigmoid,
    tune,
)

_FX, _FY, _CX, _CY = SMALL.fx, SMALL.fy, SMALL.cx, SMALL.cy


# ------------------------------------------------------------------------------ helpers


def _frames_with_known_scores(seed: int, n: int = 12):
    """Random logits whose object pixels score higher on average, plus labels and valid masks."""
    rng = np.random.default_rng(seed)
    out = []
    for i in range(n):
        lab = (rng.random((20, 30)) < rng.uniform(0.0, 0.5)).astype(np.uint8)
        if i == 0:
            lab[:] = 0  # a frame without objects exercises the 0/0 conventions
        lg = np.where(lab == 1, rng.normal(1.0, 1.2, lab.shape), rng.normal(-1.0, 1.5, lab.shape)).astype(np.float32)
        valid = rng.random(lab.shape) > 0.1
        out.append((lg, lab, valid))
    return out


def _metrics_at(frames, logit: float):
    acc = MetricAccumulator()
    for lg, lab, valid in frames:
        acc.add(lg >= logit, lab, valid)
    return acc.summary()


def _fbeta(p: float, r: float, beta: float) -> float:
    b2 = beta * beta
    return (1 + b2) * p * r / (b2 * p + r) if (b2 * p + r) > 0 else 0.0


class FakePredictor:
    """Returns pre-computed logits per frame (keyed by stamp): tune() without a network."""

    def __init__(self, logits_by_stamp: dict[int, np.ndarray], threshold: float = 0.5) -> None:
        self._l = logits_by_stamp
        self.meta = ModelMeta(threshold=threshold)
        self.name = "fake"

    def logits(self, depth: np.ndarray) -> np.ndarray:
        return self._l[round(float(depth[0, 0]) * 1e6)]


def _frame_objs(items):
    """(logits, label) pairs -> Frame objects whose depth encodes the key for FakePredictor."""
    from edge.io import Frame

    frames, table = [], {}
    for k, (lg, lab) in enumerate(items):
        depth = np.full(lab.shape, 0.3, np.float32)
        depth[0, 0] = (k + 1) * 1e-6
        table[k + 1] = lg
        frames.append(Frame(depth=depth, stamp_ns=k, label=lab))
    return frames, FakePredictor(table)


# ------------------------------------------------------------------------------ the sweep


@pytest.mark.parametrize("objective", ["iou", "f1", "f0.5", "f2", "precision>=0.7", "recall>=0.9"])
def test_sweep_picks_the_optimum_that_edge_metrics_confirms(objective):
    frames = _frames_with_known_scores(0)
    edges = np.unique(np.concatenate([np.linspace(-4, 4, 161), [0.0]]))  # small grid: brute force is cheap
    sw = ThresholdSweep(edges)
    for lg, lab, valid in frames:
        sw.add(lg, lab, valid)
    obj = parse_objective(objective)
    choice = choose_threshold(sw.curves(), obj)

    def value(s):
        return {
            "iou": s.iou,
            "fbeta": _fbeta(s.precision, s.recall, obj.beta),
            "precision": s.recall,
            "recall": s.precision,
        }[obj.kind]

    def feasible(s):
        return not obj.constrained or getattr(s, obj.kind) >= obj.target - 1e-12

    brute = [(value(s), e) for e in edges if feasible(s := _metrics_at(frames, e))]
    best = max(v for v, _ in brute)
    chosen = _metrics_at(frames, choice.logit)
    assert feasible(chosen)
    assert value(chosen) == pytest.approx(best, abs=1e-12)
    assert choice.value == pytest.approx(best, abs=1e-12)
    assert choice.threshold == pytest.approx(1 / (1 + math.exp(-choice.logit)))


def test_sweep_curves_equal_edge_metrics_at_every_probed_threshold():
    frames = _frames_with_known_scores(1)
    sw = ThresholdSweep()
    for lg, lab, valid in frames:
        sw.add(lg, lab, valid)
    c = sw.curves()
    for i in (0, 1500, c.index_of(0.0), 5000, 7000, len(c.edges) - 1):
        s = _metrics_at(frames, c.edges[i])
        assert (c.iou[i], c.precision[i], c.recall[i], c.pixel_accuracy[i], c.pooled_iou[i]) == pytest.approx(
            (s.iou, s.precision, s.recall, s.pixel_accuracy, s.pooled_iou), abs=1e-12
        )


def test_separable_logits_give_a_threshold_in_the_gap_with_perfect_iou():
    rng = np.random.default_rng(3)
    lab = (rng.random((40, 40)) < 0.3).astype(np.uint8)
    lg = np.where(lab == 1, rng.uniform(1.2, 3.0, lab.shape), rng.uniform(-2.0, 0.8, lab.shape))
    sw = ThresholdSweep()
    sw.add(lg, lab)
    choice = choose_threshold(sw.curves(), parse_objective("iou"))
    assert 0.8 < choice.logit <= 1.2
    assert abs(choice.logit - 1.0) < 0.05  # the middle of the gap: the largest margin
    assert choice.value == 1.0


def test_precision_and_recall_targets_on_a_hand_built_frame():
    # 100 object pixels at logit 2; 1000 background pixels at -1 and 10 at 3.
    # threshold in (-1, 2]: precision 100/110 = 0.909, recall 1 -> precision>=0.9 picks it.
    lab = np.zeros(1110, np.uint8)
    lab[:100] = 1
    lg = np.concatenate([np.full(100, 2.0), np.full(1000, -1.0), np.full(10, 3.0)])
    sw = ThresholdSweep()
    sw.add(lg[None], lab[None])
    c = sw.curves()
    ch = choose_threshold(c, parse_objective("precision>=0.9"))
    assert -1.0 < ch.logit <= 2.0 and ch.value == 1.0
    ch = choose_threshold(c, parse_objective("recall>=0.5"))
    assert -1.0 < ch.logit <= 2.0 and ch.value == pytest.approx(100 / 110)
    with pytest.raises(ThresholdError, match=r"precision >= 0.95.*best 0.9091"):
        choose_threshold(c, parse_objective("precision>=0.95"))


def test_saturated_logits_resolve_thresholds_like_the_papers_0_9999():
    # A model that is sure of everything (logits ~ 9-10): the right boundary sits near 0.99990.
    lab = np.zeros((10, 100), np.uint8)
    lab[:, :30] = 1
    lg = np.where(lab == 1, 9.5, 8.9)
    sw = ThresholdSweep()
    sw.add(lg, lab)
    ch = choose_threshold(sw.curves(), parse_objective("iou"))
    assert sigmoid(8.9) < ch.threshold <= sigmoid(9.5)
    assert ch.threshold != 1.0 and ch.value == 1.0
    assert ModelMeta(threshold=ch.threshold).threshold == ch.threshold  # storable


def test_logits_beyond_the_grid_are_counted_and_nan_is_refused():
    edges = logit_grid()
    assert edges[0] == -LOGIT_LIMIT and edges[-1] == LOGIT_LIMIT and 0.0 in edges
    sw = ThresholdSweep(edges)
    lab = np.array([[1, 1, 0, 0]], np.uint8)
    sw.add(np.array([[1e6, np.inf, -np.inf, -1e6]]), lab)
    c = sw.curves()
    assert c.iou[c.index_of(0.0)] == 1.0 and c.iou[0] == 1.0 and c.iou[-1] == 1.0
    with pytest.raises(ModelError, match="NaN"):
        sw.add(np.array([[np.nan, 0, 0, 0]]), lab)


def test_frames_without_valid_pixels_are_skipped_like_edge_metrics():
    sw = ThresholdSweep()
    assert sw.add(np.zeros((3, 3)), np.ones((3, 3)), np.zeros((3, 3), bool)) is False
    assert sw.skipped == 1 and sw.frames == 0
    with pytest.raises(DataError):
        sw.curves()


# ------------------------------------------------------------------------------ objectives


@pytest.mark.parametrize(
    "text, kind, beta, target",
    [
        ("iou", "iou", 1.0, 0.0),
        ("IoU", "iou", 1.0, 0.0),
        ("f1", "fbeta", 1.0, 0.0),
        ("F2", "fbeta", 2.0, 0.0),
        ("f0.5", "fbeta", 0.5, 0.0),
        ("precision>=0.98", "precision", 1.0, 0.98),
        ("recall >= 0.9", "recall", 1.0, 0.9),
        ("p>=.95", "precision", 1.0, 0.95),
        ("precision>=1", "precision", 1.0, 1.0),
    ],
)
def test_objective_forms_parse(text, kind, beta, target):
    o = parse_objective(text)
    assert (o.kind, o.beta, o.target) == (kind, beta, target)
    assert parse_objective(o.text) == o  # the canonical text round-trips


@pytest.mark.parametrize(
    "text", ["", "f", "fx", "f0", "accuracy", "precision>0.9", "precision>=", "precision>=-1", "recall>=0", "iou2", "f1,iou"]
)
def test_malformed_objectives_raise_config_error_listing_valid_forms(text):
    with pytest.raises(ConfigError, match="valid forms: iou, f1, fBETA"):
        parse_objective(text)


def test_impossible_targets_raise_threshold_error_before_any_frame():
    with pytest.raises(ThresholdError, match="at most 1"):
        parse_objective("precision>=1.01").check_attainable()
    with pytest.raises(ThresholdError, match="not 98"):
        parse_objective("recall>=98").check_attainable()
    parse_objective("precision>=1").check_attainable()


# ------------------------------------------------------------------------------ split and tune()


def test_heldout_split_is_exact_and_deterministic_by_seed():
    for split in (0.1, 0.25, 0.5):
        for seed in range(5):
            h = heldout_assigner(split, seed)
            picks = [h(i) for i in range(200)]
            assert sum(picks) in (math.floor(200 * split), math.ceil(200 * split))
            assert picks == [heldout_assigner(split, seed)(i) for i in range(200)]
    assert [heldout_assigner(0.3, 1)(i) for i in range(50)] != [heldout_assigner(0.3, 2)(i) for i in range(50)]
    with pytest.raises(ConfigError, match="split"):
        heldout_assigner(1.0, 0)


def test_tune_reports_heldout_before_and_after_exactly():
    data = _frames_with_known_scores(4, n=20)
    frames, pred = _frame_objs([(lg, lab) for lg, lab, _ in data])
    res = tune(pred, frames, "iou", split=0.25, seed=0)
    assert res.tuning.frames == 15 and res.heldout.frames == 5
    held = [f for i, f in enumerate(frames) if heldout_assigner(0.25, 0)(i)]
    held_data = [(pred.logits(f.depth), f.label, np.ones(f.label.shape, bool)) for f in held]
    assert res.before()["iou"] == pytest.approx(_metrics_at(held_data, 0.0).iou, abs=1e-12)
    assert res.after()["iou"] == pytest.approx(_metrics_at(held_data, res.choice.logit).iou, abs=1e-12)
    assert res.before()["threshold"] == 0.5
    d = res.to_dict()
    assert {"threshold", "objective", "before", "after", "heldout_frames"} <= set(d)
    assert "held-out (5 frames)" in res.policy("x")


def test_tune_without_labels_is_a_data_error_with_the_hint():
    from edge.io import Frame

    frames = [Frame(depth=np.full((4, 4), 0.3, np.float32), stamp_ns=i) for i in range(3)]
    with pytest.raises(DataError, match=r"no labelled frames.*3 frames without labels.*topics present: /a"):
        tune(FakePredictor({}), frames, no_labels_hint="topics present: /a")


# ------------------------------------------------------------------------------ CLI and storage


def _scene(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    from edge.sampleframes import synthetic_frame

    return synthetic_frame(rng, SMALL)


@pytest.fixture(scope="module")
def data_dir(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("tune_data")
    rng = np.random.default_rng(7)
    with FrameWriter(d / "labelled.mcap") as w:
        for i in range(16):
            depth, lab = _scene(rng)
            w.write(1_000_000 * (i + 1), depth, lab, intrinsics=(_FX, _FY, _CX, _CY))
    (d / "unlabelled").mkdir()
    with FrameWriter(d / "unlabelled" / "rec.mcap") as w:
        for i in range(6):
            depth, _ = _scene(rng)
            w.write(1_000_000 * (i + 1), depth, None, intrinsics=(_FX, _FY, _CX, _CY))
    return d


def _export(pt: Path, out: Path) -> Path:
    from tinymodel import export_checkpoint

    return export_checkpoint(pt, out)


def _cli(capsys, *argv: str) -> tuple[int, str, str]:
    from edge.tune_cli import main

    rc = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return rc, out, err


def test_cli_tunes_a_checkpoint_and_writes_threshold_and_policy(capsys, data_dir, tiny_pt, tmp_path):
    from edge.train.checkpoint import read_checkpoint

    out = tmp_path / "tuned.pt"
    plot = tmp_path / "pr.png"
    rc, stdout, err = _cli(capsys, "--model", tiny_pt, "--data", data_dir / "labelled.mcap", "--objective", "f1",
                           "--out", out, "--json", "--plot", plot)
    assert rc == 0, err
    d = json.loads(stdout)
    assert {"threshold", "objective", "before", "after", "heldout_frames", "policy"} <= set(d)
    assert d["objective"] == "f1" and d["heldout_frames"] == 4 and d["tuning_frames"] == 12
    assert d["before"]["threshold"] == 0.5 and d["after"]["threshold"] == d["threshold"]
    meta = ModelMeta.from_dict(read_checkpoint(out)["meta"])
    # --out always gets a model: the tuned threshold if it beats the stored one on the held-out frames
    assert meta.threshold == d["result_threshold"] == (d["threshold"] if d["improves"] else 0.5)
    assert meta.threshold_policy == d["policy"] and "depthseg-tune objective f1" in meta.threshold_policy
    assert ModelMeta.from_dict(read_checkpoint(tiny_pt)["meta"]).threshold == 0.5  # --out left the input alone
    assert plot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.slow
def test_threshold_survives_export_of_a_tuned_checkpoint(capsys, data_dir, tiny_pt, tmp_path):
    from edge.infer import Segmenter
    from edge.train.threshold_store import read_meta

    tuned = tmp_path / "tuned.pt"
    rc, stdout, err = _cli(capsys, "--model", tiny_pt, "--data", data_dir, "--objective", "recall>=0.9",
                           "--out", tuned, "--json")
    assert rc == 0, err
    d = json.loads(stdout)
    onnx_path = _export(tuned, tmp_path / "tuned.onnx")
    seg = Segmenter(onnx_path, threads=1)
    assert seg.threshold == d["threshold"] == read_meta(onnx_path).threshold
    assert seg.meta.threshold_policy == d["policy"]
    assert seg.props["threshold"] == repr(d["threshold"])


def test_cli_tunes_onnx_in_place_with_backup_and_the_edge_reads_it(capsys, data_dir, tiny_onnx, tmp_path):

    from onnxgen import linear_model

    from edge.infer import Segmenter

    # nearer than the frame mean = object; the stored 0.01 calls much of the table object too
    model = linear_model(tmp_path / "m.onnx", k=4.0, threshold=0.01)
    before_props = dict(Segmenter(model, threads=1).props)
    # in-sample (--split 0): the chosen threshold is better than 0.5 on the frames it is judged on
    rc, stdout, err = _cli(capsys, "--model", model, "--data", data_dir / "labelled.mcap", "--json", "--split", "0")
    assert rc == 0, err
    d = json.loads(stdout)
    assert d["improves"] and not d["kept"]
    assert d["written"] == str(model) and d["backup"] == str(model) + ".bak"
    seg = Segmenter(model, threads=1)
    assert seg.threshold == d["threshold"] == float(seg.props["threshold"])
    assert seg.props["threshold_policy"] == d["policy"] == seg.meta.threshold_policy
    assert ModelMeta.from_onnx_props(seg.props).with_(threshold=0.01, threshold_policy="default 0.5 (paper)") == \
        ModelMeta.from_onnx_props(before_props)  # nothing but the threshold changed
    assert {k: v for k, v in seg.props.items() if not k.startswith(("threshold", "depthseg"))} == \
        {k: v for k, v in before_props.items() if not k.startswith(("threshold", "depthseg"))}
    backup = Segmenter(Path(d["backup"]), threads=1)
    assert backup.threshold == 0.01
    # eval and replay use the stored threshold by default
    from edge.eval_cli import main as eval_main

    assert eval_main(["--model", str(model), "--data", str(data_dir / "labelled.mcap"), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["threshold"] == d["threshold"]
    from edge.io.reader import open_depth_stream
    from replay.replay import replay

    summary = replay(open_depth_stream(data_dir / "labelled.mcap"), seg)
    assert summary.threshold == d["threshold"] and summary.to_dict()["threshold"] == d["threshold"]


def test_pseudo_labels_are_reported_and_stored_as_such(capsys, data_dir, tiny_onnx, tmp_path):
    out = tmp_path / "pseudo.onnx"
    rc, stdout, err = _cli(capsys, "--model", tiny_onnx, "--data", data_dir / "unlabelled", "--pseudo-labels",
                           "--out", out, "--split", "0.34")
    assert rc == 0, err
    assert "pseudo-labels" in stdout and "NOT ground truth" in stdout
    from edge.train.threshold_store import read_meta

    assert "PSEUDO-LABELS, not ground truth" in read_meta(out).threshold_policy


def test_cli_without_labels_fails_with_one_line_naming_topics(capsys, data_dir, tiny_pt):
    rc, out, err = _cli(capsys, "--model", tiny_pt, "--data", data_dir / "unlabelled", "--dry-run")
    assert rc == 2 and out == ""
    assert err.count("\n") == 1 and "no labels found" in err and "topics present: /pico_flexx/camera_info" in err
    assert "--pseudo-labels" in err


@pytest.mark.parametrize(
    "objective, match",
    [("precision>=1.01", "at most 1"), ("accuracy", "valid forms"), ("precision>=1", "no threshold reaches")],
)
def test_cli_objective_errors_are_one_line_and_nonzero(capsys, data_dir, tmp_path, tiny_pt, objective, match):
    # labels that are pure noise: no threshold gives every frame a perfect precision
    rng = np.random.default_rng(11)
    path = tmp_path / "noise.mcap"
    with FrameWriter(path) as w:
        for i in range(8):
            depth, _ = _scene(rng)
            w.write(i + 1, depth, (rng.random((H, W)) < 0.5).astype(np.uint8))
    rc, out, err = _cli(capsys, "--model", tiny_pt, "--data", path, "--objective", objective, "--dry-run")
    assert rc == 2 and out == ""
    assert err.count("\n") == 1 and err.startswith("depthseg-tune: error:") and match in err


def test_store_refuses_mismatched_out_and_missing_model(tmp_path, tiny_pt):
    from edge.train.threshold_store import store_threshold

    with pytest.raises(ModelError, match="model's type"):
        store_threshold(tiny_pt, 0.7, "p", out=tmp_path / "x.onnx")
    with pytest.raises(ModelError, match="no such model"):
        store_threshold(tmp_path / "missing.pt", 0.7, "p")
    with pytest.raises(ModelError, match=r"\(0, 1\)"):
        store_threshold(tiny_pt, 1.0, "p", out=tmp_path / "y.pt")


@pytest.mark.slow
def test_int8_model_is_tuned_on_its_own_outputs_and_keeps_the_threshold(capsys, data_dir, tiny_onnx, tmp_path):
    from edge.eval_cli import main as eval_main
    from edge.infer import Segmenter
    from edge.sampleframes import synthetic_frames
    from export.quantize import quantize_int8

    q = quantize_int8(tiny_onnx, tmp_path / "tiny-int8.onnx", synthetic_frames(4, 0, sensor=SMALL))
    assert Segmenter(q, threads=1).precision == "int8"
    tuned = tmp_path / "tiny-int8-tuned.onnx"
    data = data_dir / "labelled.mcap"
    rc, stdout, err = _cli(capsys, "--model", q, "--data", data, "--split", "0", "--out", tuned, "--json")
    assert rc == 0, err
    d = json.loads(stdout)
    assert d["in_sample"] and d["tuning_frames"] == 16
    seg = Segmenter(tuned, threads=1)
    assert seg.precision == "int8" and seg.threshold == d["threshold"]
    assert "int8_check" not in seg.props or seg.props["int8_check"] == Segmenter(q, threads=1).props["int8_check"]
    # depthseg-eval runs the int8 file at its stored threshold and sees exactly what tune measured
    assert eval_main(["--model", str(tuned), "--data", str(data), "--json"]) == 0
    ev = json.loads(capsys.readouterr().out)
    assert ev["threshold"] == d["threshold"]
    assert (ev["iou"], ev["precision"], ev["recall"]) == pytest.approx(
        (d["after"]["iou"], d["after"]["precision"], d["after"]["recall"]), abs=1e-12
    )


def test_without_model_the_shipped_default_is_never_rewritten_its_tuned_copy_goes_to_the_user_dir(
    capsys, monkeypatch, data_dir, tiny_pt, tiny_onnx, tmp_path
):
    import shutil

    from onnxgen import linear_model

    from edge import defaults
    from edge.train.threshold_store import read_meta

    pt, onnx_path = tmp_path / "default.pt", linear_model(tmp_path / "default.onnx", k=4.0, threshold=0.01)
    shutil.copy(tiny_pt, pt)
    before = onnx_path.read_bytes(), pt.read_bytes()
    monkeypatch.setattr(defaults, "DEFAULT_CHECKPOINT", pt)
    monkeypatch.setattr(defaults, "DEFAULT_ONNX", onnx_path)
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "xdg"))
    rc, stdout, err = _cli(capsys, "--data", data_dir / "labelled.mcap", "--split", "0")
    assert rc == 0, err
    user = tmp_path / "xdg" / "depthseg" / "models" / "default.onnx"
    assert f"wrote threshold into {user}" in stdout and "shipped model is never rewritten" in stdout
    assert (onnx_path.read_bytes(), pt.read_bytes()) == before  # the shipped files are untouched
    assert not list(tmp_path.glob("*.bak"))
    assert read_meta(user).threshold != 0.01
    # naming the shipped file itself is the same: it is the shipped default wherever it lives
    rc, stdout, err = _cli(capsys, "--model", onnx_path, "--data", data_dir / "labelled.mcap", "--split", "0", "--json")
    assert rc == 0, err
    d = json.loads(stdout)
    assert d["destination"] == "user" and d["written"] == str(user)
    assert (onnx_path.read_bytes(), pt.read_bytes()) == before


def test_the_shipped_fast_model_is_never_rewritten_either(tmp_path, monkeypatch):
    from edge import defaults
    from edge.commands import tune_destination

    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "xdg"))
    user = tmp_path / "xdg" / "depthseg" / "models"
    assert tune_destination(defaults.FAST_ONNX, None, False) == (user / "fast.onnx", "user")
    assert tune_destination(defaults.FAST_CHECKPOINT, None, False) == (user / "fast.pt", "user")
    own = tmp_path / "fast.onnx"  # a user's file of the same name is theirs: rewritten in place
    own.write_bytes(defaults.FAST_ONNX.read_bytes())
    assert tune_destination(own, None, False) == (own, "in place")


def test_the_stored_threshold_is_kept_unless_the_new_one_is_better_on_heldout_frames():
    """Issue 11: a tuned 0.671 was replaced by 0.572 after the report called the new one worse."""
    rng = np.random.default_rng(3)
    items = []
    for _ in range(12):
        lab = (rng.random((20, 30)) < 0.3).astype(np.uint8)
        items.append((np.where(lab > 0, 2.0, -2.0) + rng.normal(0, 1.5, lab.shape), lab))
    frames, pred = _frame_objs(items)
    pred.meta = ModelMeta(threshold=0.671)
    res = tune(pred, frames, "iou", split=0.5, seed=0)
    assert res.before()["threshold"] == pytest.approx(0.671)  # compared with the stored one, not 0.5
    worse = res.after()["objective"] <= res.before()["objective"]
    assert res.improves is (not worse)
    assert res.result_threshold == (0.671 if worse else res.threshold)
    if worse:
        assert res.policy().startswith("kept the stored threshold 0.671")
    # in-sample the optimum can only be as good or better; the stored optimum itself is kept
    res0 = tune(pred, frames, "iou", split=0.0, seed=0)
    pred.meta = ModelMeta(threshold=res0.threshold)
    frames, _ = _frame_objs(items)
    again = tune(pred, frames, "iou", split=0.0, seed=0)
    assert not again.improves and again.result_threshold == pytest.approx(res0.threshold)

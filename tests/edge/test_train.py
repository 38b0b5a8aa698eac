"""Training: a tiny run lowers the loss, resume continues where it stopped, bad input is one line."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from edge.errors import ConfigError, DataError, ModelError
from edge.meta import ModelMeta
from edge.train.checkpoint import load_checkpoint, read_checkpoint
from edge.train.data import FrameSet, load_frames, make_batch, prepare_frames, prepared_bytes, split_indices
from edge.train.loop import TrainConfig, train
from edge.train.losses import boundary_band, boundary_band_by_pooling, masked_bce, soft_jaccard
from edge.train_cli import main as train_main

META = ModelMeta(encoder="vgg11", width=0.125, batch_norm=True)


def _frames(n: int = 24, seed: int = 0) -> FrameSet:
    """Tilted floor with raised boxes (label 1) and dead corners, 40 x 56 (padded to 64 x 64)."""
    rng = np.random.default_rng(seed)
    h, w = 40, 56
    yy, xx = np.mgrid[0:h, 0:w]
    depths, labels = [], []
    for _ in range(n):
        d = 0.30 + 0.0005 * xx + rng.normal(0, 0.001, (h, w))
        lab = np.zeros((h, w), np.uint8)
        for _k in range(rng.integers(1, 3)):
            y, x = rng.integers(0, h - 12), rng.integers(0, w - 12)
            d[y : y + 10, x : x + 10] -= 0.05
            lab[y : y + 10, x : x + 10] = 1
        d[:3, :3] = 0.0
        depths.append(d.astype(np.float32))
        labels.append(lab)
    return FrameSet(np.stack(depths), np.stack(labels))


def test_masked_bce_ignores_masked_pixels() -> None:
    logits = torch.tensor([[[[10.0, -10.0]]]])
    target = torch.tensor([[[[1.0, 1.0]]]])
    only_first = masked_bce(logits, target, torch.tensor([[[[1.0, 0.0]]]]))
    assert float(only_first) < 1e-3  # the badly wrong second pixel is masked out
    both = masked_bce(logits, target, torch.ones_like(target))
    assert float(both) > 4.0


def test_make_batch_masks_padding_and_invalid_pixels() -> None:
    fs = _frames(2)
    x, t, m = make_batch(fs, np.array([0, 1]), ModelMeta(in_channels=3, pad_multiple=32))
    assert x.shape == (2, 3, 64, 64) and t.shape == m.shape == (2, 1, 64, 64)
    assert m[:, :, 40:, :].sum() == 0 and m[:, :, :, 56:].sum() == 0  # padding never reaches the loss
    assert m[0, 0, 0, 0] == 0  # dead corner pixel excluded
    assert np.array_equal(x[:, 0], x[:, 1])  # replicated channels


def test_tiny_training_lowers_the_loss(tmp_path) -> None:
    fs = _frames(32)
    cfg = TrainConfig(epochs=4, batch_size=8, lr=1e-2, patience=10, seed=0, threads=1)
    res = train(META, fs.subset(np.arange(24)), fs.subset(np.arange(24, 32)), tmp_path, cfg)
    losses = [h["val_loss"] for h in res.history]
    assert len(losses) == 4
    assert min(losses[1:]) < losses[0]
    assert res.history[-1]["train_loss"] < res.history[0]["train_loss"]
    model, meta, blob = load_checkpoint(tmp_path / "best.pt")
    assert blob["epoch"] == res.best_epoch
    assert meta.training["epochs_run"] == 4 and meta.params > 0
    assert (tmp_path / "log.csv").read_text().count("\n") == 5
    assert (tmp_path / "loss.png").stat().st_size > 1000


def test_resume_continues_from_the_last_epoch(tmp_path) -> None:
    fs = _frames(16)
    tr, va = fs.subset(np.arange(12)), fs.subset(np.arange(12, 16))
    train(META, tr, va, tmp_path, TrainConfig(epochs=2, batch_size=8, seed=0, threads=1))
    assert read_checkpoint(tmp_path / "last.pt")["epoch"] == 2
    res = train(META, tr, va, tmp_path, TrainConfig(epochs=3, batch_size=8, seed=0, threads=1), resume=True)
    assert [h["epoch"] for h in res.history] == [1, 2, 3]
    assert read_checkpoint(tmp_path / "last.pt")["epoch"] == 3
    with pytest.raises(ConfigError, match="width"):
        train(META.with_(width=0.25), tr, va, tmp_path, TrainConfig(epochs=4, threads=1), resume=True)


def test_resume_without_checkpoint_is_a_clear_error(tmp_path) -> None:
    fs = _frames(6)
    with pytest.raises(ModelError, match="nothing to resume"):
        train(META, fs, fs, tmp_path / "new", TrainConfig(epochs=1, threads=1), resume=True)


def test_split_is_deterministic_and_disjoint() -> None:
    a = split_indices(100, (0.7, 0.2, 0.1), seed=3)
    b = split_indices(100, (0.7, 0.2, 0.1), seed=3)
    assert all(np.array_equal(x, y) for x, y in zip(a, b))
    assert [len(x) for x in a] == [70, 20, 10]
    assert len(set(np.concatenate(a).tolist())) == 100


@pytest.mark.parametrize(
    "argv, needle",
    [
        (["--data", "/nonexistent/dir", "--out", "OUT"], "no such file or directory"),
        (["--out", "OUT"], "give either --data"),
        (["--data", "x", "--out", "OUT", "--split", "0.5,0.5"], "--split"),
        (["--data", "x", "--out", "OUT", "--epochs", "0"], "epochs"),
        (["--data", "x", "--out", "OUT", "--encoder", "resnet"], "unknown encoder"),
        (["--data", "x", "--out", "OUT", "--jaccard", "-1"], "jaccard weight"),
        (["--data", "x", "--out", "OUT", "--jaccard", "nan"], "jaccard weight"),
        (["--data", "x", "--out", "OUT", "--boundary-weight", "-1"], "boundary weight"),
        (["--data", "x", "--out", "OUT", "--boundary-weight", "inf"], "boundary weight"),
        (["--data", "x", "--out", "OUT", "--crop", "32"], "--crop must be HEIGHTxWIDTH"),
        (["--data", "x", "--out", "OUT", "--crop", "0x32"], "--crop must be HEIGHTxWIDTH"),
        (["--data", "x", "--out", "OUT", "--crop", "64x32"], "crop 64x32 is larger than the frames (40x56)"),
        (["--data", "x", "--out", "OUT", "--crop", "32x40"], "must be multiples of 32"),
        (["--data", "x", "--out", "OUT", "--crop", "32x32", "--no-augment"], "crop window is a random augmentation"),
        (["--data", "x", "--out", "OUT", "--crop-epochs", "2"], "give a crop too"),
        (["--data", "x", "--out", "OUT", "--crop", "32x32", "--crop-epochs", "-1"], "crop epochs must be"),
    ],
)
def test_cli_bad_input_is_one_line(argv, needle, tmp_path, capsys, monkeypatch) -> None:
    monkeypatch.chdir(tmp_path)
    if "x" in argv:
        _write_tiny_mcap(tmp_path / "x")
    rc = train_main(argv)
    err = capsys.readouterr().err.strip()
    assert rc == 2
    assert "\n" not in err and needle in err and "Traceback" not in err


def _write_tiny_mcap(d) -> None:
    from edge.io import FrameWriter

    d.mkdir()
    fs = _frames(4)
    with FrameWriter(d / "a.mcap") as w:
        for i in range(len(fs)):
            w.write(i * 1000, fs.depth[i], fs.label[i])


class _Evil:
    """Unpickling this would create a file: the code-execution class of issue 11."""

    def __init__(self, target: str) -> None:
        self.target = target

    def __reduce__(self):
        return (open, (self.target, "w"))


def test_a_checkpoint_that_would_run_code_is_refused_and_runs_nothing(tmp_path) -> None:
    target = tmp_path / "pwned"
    bad = tmp_path / "evil.pt"
    torch.save({"format": "depthseg-checkpoint", "payload": _Evil(str(target))}, bad)
    with pytest.raises(ModelError, match="not a readable depthseg checkpoint"):
        read_checkpoint(bad)
    assert not target.exists()


def test_weight_average_is_what_is_validated_kept_and_resumed(tmp_path) -> None:
    fs = _frames(16)
    tr, va = fs.subset(np.arange(12)), fs.subset(np.arange(12, 16))
    cfg = TrainConfig(epochs=1, batch_size=4, lr=1e-2, seed=0, threads=1, ema=0.9)
    train(META, tr, va, tmp_path, cfg)
    last, best = read_checkpoint(tmp_path / "last.pt"), read_checkpoint(tmp_path / "best.pt")
    avg = last["weight_average"]
    assert avg["updates"] == 3  # one update per step: 12 frames / batch 4
    conv = [k for k, v in last["state_dict"].items() if v.dtype.is_floating_point and v.ndim == 4]
    # best.pt (epoch 1, always an improvement) holds the average, last.pt the last step's weights
    assert all(torch.equal(best["state_dict"][k], avg["state_dict"][k]) for k in conv)
    assert not all(torch.equal(avg["state_dict"][k], last["state_dict"][k]) for k in conv)
    train(META, tr, va, tmp_path, TrainConfig(epochs=3, batch_size=4, lr=1e-2, seed=0, threads=1, ema=0.9),
          resume=True)
    assert read_checkpoint(tmp_path / "last.pt")["weight_average"]["updates"] == 3 * 3


def test_resume_must_keep_the_runs_weight_average_setting(tmp_path) -> None:
    fs = _frames(8)
    tr, va = fs.subset(np.arange(6)), fs.subset(np.arange(6, 8))
    train(META, tr, va, tmp_path / "plain", TrainConfig(epochs=1, batch_size=4, threads=1))
    with pytest.raises(ConfigError, match="without a weight average"):
        train(META, tr, va, tmp_path / "plain", TrainConfig(epochs=2, batch_size=4, threads=1, ema=0.9), resume=True)
    train(META, tr, va, tmp_path / "avg", TrainConfig(epochs=1, batch_size=4, threads=1, ema=0.9))
    with pytest.raises(ConfigError, match="with a weight average"):
        train(META, tr, va, tmp_path / "avg", TrainConfig(epochs=2, batch_size=4, threads=1), resume=True)


def test_weight_average_decay_must_be_below_one() -> None:
    with pytest.raises(ConfigError, match="ema decay"):
        TrainConfig(ema=1.0)


def test_soft_jaccard_is_per_frame_and_ignores_masked_pixels() -> None:
    target = torch.zeros(3, 1, 4, 4)
    target[0, 0, :2, :2] = 1  # frame 0: a 4 px object; frames 1 and 2: empty tables
    logits = torch.where(target > 0, 20.0, -20.0)
    logits[1, 0, 0, :2] = 20.0  # frame 1: two stray object pixels on an empty table
    mask = torch.ones_like(target)
    j = soft_jaccard(logits, target, mask)
    assert j.shape == (3,)
    assert float(j[0]) < 1e-6 and float(j[2]) < 1e-6  # right answers cost nothing
    assert abs(float(j[1]) - 2 / 3) < 1e-4  # 1 - smooth / (2 stray + smooth)
    mask[1, 0, 0, :2] = 0  # the stray pixels are invalid: they never count
    assert float(soft_jaccard(logits, target, mask)[1]) < 1e-6


@pytest.mark.parametrize("term, value", [("jaccard", 0.5), ("boundary", 2.0)])
def test_a_loss_term_trains_and_is_recorded_while_the_logged_loss_stays_bce(tmp_path, term, value) -> None:
    fs = _frames(16)
    tr, va = fs.subset(np.arange(12)), fs.subset(np.arange(12, 16))
    base = dict(epochs=2, batch_size=4, lr=1e-2, seed=0, threads=1)
    plain = train(META, tr, va, tmp_path / "plain", TrainConfig(**base))
    with_term = train(META, tr, va, tmp_path / term, TrainConfig(**base, **{term: value}))
    # the first logged batch loss is the same masked BCE of the same weights, with or without the term
    b0 = [read_checkpoint(r / "last.pt")["batch_losses"][0] for r in (tmp_path / "plain", tmp_path / term)]
    assert b0[0] == pytest.approx(b0[1], rel=1e-6)
    # ...but the term changes the gradient, so the weights part after the first step
    assert plain.history[-1]["train_loss"] != with_term.history[-1]["train_loss"]
    assert read_checkpoint(tmp_path / term / "best.pt")["meta"]["training"]["config"][term] == value


def test_boundary_band_is_two_pixels_either_side_of_an_outline() -> None:
    target = torch.zeros(1, 1, 12, 12)
    target[0, 0, 3:9, 3:9] = 1  # a 6 x 6 object
    band = boundary_band(target)[0, 0]
    assert band.shape == (12, 12) and set(band.unique().tolist()) == {0.0, 1.0}
    assert band[5, 1] == 1 and band[5, 2] == 1 and band[5, 3] == 1 and band[5, 4] == 1  # 2 px out, 2 px in
    assert band[5, 0] == 0 and band[5, 5] == 0 and band[6, 6] == 0  # farther: the table, the interior
    assert float(boundary_band(torch.zeros(1, 1, 8, 8)).sum()) == 0  # no object, no band
    assert float(boundary_band(torch.ones(1, 1, 8, 8)).sum()) == 0  # one object filling the frame


@pytest.mark.parametrize("px", [1, 2, 3])
def test_boundary_band_by_box_sums_equals_dilation_minus_erosion(px) -> None:
    g = torch.Generator().manual_seed(px)
    blobs = torch.nn.functional.avg_pool2d(torch.rand(4, 1, 37, 53, generator=g), 7, 1, 3)
    target = (blobs > 0.5).float()  # objects of any shape, cut by every border
    target[0] = 0  # an empty frame
    target[1] = 1  # an object filling the frame
    target[2, :, ::2, ::3] = 1 - target[2, :, ::2, ::3]  # single-pixel speckle
    band = boundary_band(target, px)
    assert band.dtype == target.dtype and float(band[2].sum()) > 0
    assert torch.equal(band, boundary_band_by_pooling(target, px))  # bit for bit
    soft = target * 0.5  # not 0/1: the max pools are the rule
    assert torch.equal(boundary_band(soft, px), boundary_band_by_pooling(soft, px))


def test_a_wall_clock_budget_stops_early_and_says_so(tmp_path, capsys) -> None:
    fs = _frames(8)
    tr, va = fs.subset(np.arange(6)), fs.subset(np.arange(6, 8))
    res = train(META, tr, va, tmp_path / "r", TrainConfig(epochs=3, batch_size=4, threads=1, max_minutes=1e-6))
    assert res.epochs_run == 1 and res.stopped == "max_minutes"
    full = train(META, tr, va, tmp_path / "f", TrainConfig(epochs=2, batch_size=4, threads=1, max_minutes=1e-6 + 1e3))
    assert full.epochs_run == 2 and full.stopped == ""
    _write_tiny_mcap(tmp_path / "x")
    rc = train_main(["--data", str(tmp_path / "x"), "--out", str(tmp_path / "cli"), "--epochs", "3", "--width", "0.0625",
                     "--batch-size", "2", "--threads", "1", "--max-minutes", "1e-6", "--split", "0.5,0.5,0"])
    err = capsys.readouterr().err
    assert rc == 0 and "stopped after epoch 1 of 3" in err and "--resume" in err


def test_the_training_record_names_what_made_each_data_set(tmp_path) -> None:
    import json

    from edge.train.data import data_identity

    sim = tmp_path / "sim"
    sim.mkdir()
    man = {"tool": "depthseg-sim", "seed": 1, "frames": 20000, "config_digest": "abc", "shards": {"f": {}},
           "engines": {"mujoco": "4.0.0"}, "provenance": {"git_commit": "x"}}
    (sim / "manifest.json").write_text(json.dumps(man))
    (tmp_path / "broken").mkdir()
    (tmp_path / "broken" / "manifest.json").write_text("{not json")
    got = data_identity([sim, tmp_path / "rec.mcap", tmp_path / "broken"])
    assert got[0] == {"path": str(sim), **{k: v for k, v in man.items() if k != "shards"}}  # no per-shard stats
    # with the simulator's per-shard counts, a digest of them names the frames themselves
    shard = {"file": "f", "frames": 100, "pixels": 3830400, "object_pixels": 909616, "invalid_pixels": 87797,
             "seconds": 3.6}
    (sim / "manifest.json").write_text(json.dumps({**man, "shards": {"f": shard}}))
    first = data_identity([sim])[0]["shard_counts_digest"]
    (sim / "manifest.json").write_text(json.dumps({**man, "shards": {"f": {**shard, "seconds": 9.9}}}))
    assert data_identity([sim])[0]["shard_counts_digest"] == first  # timings do not count
    (sim / "manifest.json").write_text(json.dumps({**man, "shards": {"f": {**shard, "object_pixels": 909615}}}))
    assert data_identity([sim])[0]["shard_counts_digest"] != first  # one pixel does
    assert got[1:] == [{"path": str(tmp_path / "rec.mcap")}, {"path": str(tmp_path / "broken")}]
    _write_tiny_mcap(tmp_path / "x")
    assert train_main(["--data", str(tmp_path / "x"), "--out", str(tmp_path / "cli"), "--epochs", "1", "--width",
                       "0.0625", "--batch-size", "2", "--threads", "1", "--split", "0.5,0.5,0"]) == 0
    rec = read_checkpoint(tmp_path / "cli" / "best.pt")["meta"]["training"]
    assert rec["data_identity"] == [{"path": str(tmp_path / "x")}]


def test_a_scene_split_keeps_every_view_of_a_scene_on_one_side() -> None:
    scene = np.arange(400) // 4  # 4 views a scene, as the simulator's default
    parts = split_indices(400, (0.7, 0.2, 0.1), seed=3, scene=scene)
    sides = [set(scene[p].tolist()) for p in parts]
    assert not (sides[0] & sides[1]) and not (sides[0] & sides[2]) and not (sides[1] & sides[2])
    assert [len(p) for p in parts] == [280, 80, 40] and len(set(np.concatenate(parts).tolist())) == 400
    assert all(np.array_equal(x, y) for x, y in zip(parts, split_indices(400, (0.7, 0.2, 0.1), 3, scene)))
    # the frame split shares nearly every validation scene with training
    tr, va, _ = split_indices(400, (0.7, 0.2, 0.1), seed=3)
    assert np.isin(scene[va], scene[tr]).mean() > 0.9
    # one view a scene: the scene split is the frame split, index for index
    for n, fr in ((100, (0.7, 0.2, 0.1)), (10, (0.5, 0.5, 0.0)), (5, (0.8, 0.1, 0.1))):
        same = zip(split_indices(n, fr, 1), split_indices(n, fr, 1, np.arange(n)))
        assert all(np.array_equal(x, y) for x, y in same)
    with pytest.raises(DataError, match="at least 3 scenes"):
        split_indices(8, (0.7, 0.2, 0.1), 0, np.arange(8) // 4)


def test_simulated_views_of_one_scene_load_with_one_scene_number(tmp_path) -> None:
    from sim.dataset import simulate
    from sim.generate import SimConfig

    cfg = SimConfig.from_dict({"scene": {"n_objects": [0, 2], "views_per_scene": 2}})
    simulate(tmp_path / "s", frames=6, seed=0, workers=1, shard_frames=2, config=cfg, show_progress=False)
    fs = load_frames([tmp_path / "s"])
    assert fs.scene.tolist() == [0, 0, 1, 1, 2, 2]
    assert fs.subset(np.array([5, 0])).scene.tolist() == [2, 0]


def _train_each(tmp_path, epochs: int, option: str, values: tuple[str, ...]) -> dict[str, tuple]:
    """One small training per value of a `TrainConfig` option, the rest alike: {value: (history, best, last)}."""
    fs = _frames(12)
    tr, va = fs.subset(np.arange(8)), fs.subset(np.arange(8, 12))
    runs = {}
    for value in values:
        cfg = TrainConfig(epochs=epochs, batch_size=4, lr=1e-3, seed=0, threads=1, ema=0.9, **{option: value})
        res = train(META, tr, va, tmp_path / value, cfg)
        runs[value] = (res.history, read_checkpoint(tmp_path / value / "best.pt"),
                       read_checkpoint(tmp_path / value / "last.pt"))
    return runs


def test_channels_last_training_is_the_same_arithmetic_and_stores_the_usual_layout(tmp_path) -> None:
    runs = _train_each(tmp_path, 1, "memory_format", ("channels_last", "contiguous"))
    (h_cl, best_cl, last_cl), (h_c, best_c, _) = runs["channels_last"], runs["contiguous"]
    h_cl, h_c = h_cl[0], h_c[0]
    assert h_cl["train_loss"] == pytest.approx(h_c["train_loss"], rel=1e-4)
    assert h_cl["val_loss"] == pytest.approx(h_c["val_loss"], rel=1e-4)
    diffs = []
    for k, v in best_cl["state_dict"].items():
        assert v.is_contiguous(), k  # stored NCHW whatever the training layout
        if v.dtype.is_floating_point:
            diffs.append((v - best_c["state_dict"][k]).abs().flatten())
    d = torch.cat(diffs)
    # Adam moves a weight by ~lr a step whatever its gradient's size, so a rounding-level gradient
    # near zero may step the other way: bounded by lr x steps, and rare
    assert float(d.max()) <= 2 * 1e-3 * 2
    assert float(d.mean()) < 0.1 * 1e-3  # a tenth of one step on average
    assert all(v.is_contiguous() for v in last_cl["weight_average"]["state_dict"].values())


def test_bf16_training_keeps_float32_weights_and_learns_about_as_fp32(tmp_path) -> None:
    runs = _train_each(tmp_path, 2, "precision", ("fp32", "bf16"))
    (h16, best16, last16), (h32, _, _) = runs["bf16"], runs["fp32"]
    assert all(math.isfinite(r["train_loss"]) and math.isfinite(r["val_loss"]) for r in h16)
    # bfloat16 keeps 8 bits of mantissa: the same losses to well within 1 % (0.08 % here), not to float rounding
    for a, b in zip(h16, h32):
        assert a["train_loss"] == pytest.approx(b["train_loss"], rel=0.01)
        assert a["val_loss"] == pytest.approx(b["val_loss"], rel=0.01)
    assert h16[-1]["train_loss"] < h16[0]["train_loss"] or h16[-1]["val_loss"] < h16[0]["val_loss"]
    for blob in (best16, last16):
        assert all(v.dtype == torch.float32 for v in blob["state_dict"].values() if v.dtype.is_floating_point)
    assert all(v.dtype == torch.float32 for v in last16["weight_average"]["state_dict"].values()
               if v.dtype.is_floating_point)
    assert best16["meta"]["training"]["config"]["precision"] == "bf16"


def test_an_unknown_precision_is_a_config_error() -> None:
    with pytest.raises(ConfigError, match="precision must be one of fp32, bf16"):
        TrainConfig(precision="fp16")


def test_an_unknown_memory_format_is_a_config_error() -> None:
    with pytest.raises(ConfigError, match="memory format must be one of channels_last, contiguous"):
        TrainConfig(memory_format="nhwc")


HEIGHT_META = ModelMeta(encoder="vgg11", width=0.125, batch_norm=True, in_channels=3, cues=("height",),
                        standardize="robust")


def test_frames_preprocessed_once_make_the_same_batches_without_flips() -> None:
    fs = _frames(6)
    idx = np.array([4, 0, 3])
    ps = prepare_frames(fs, HEIGHT_META)
    for got, want in zip(make_batch(ps, idx, HEIGHT_META), make_batch(fs, idx, HEIGHT_META)):
        assert got.shape == want.shape and np.array_equal(got, want)


def test_frames_preprocessed_once_flip_the_preprocessed_frame_with_the_same_draws() -> None:
    fs = _frames(4, seed=3)
    idx = np.arange(4)
    ps = prepare_frames(fs, HEIGHT_META)
    x, t, m = make_batch(ps, idx, HEIGHT_META, np.random.default_rng(7))
    x0, t0, m0 = make_batch(ps, idx, HEIGHT_META)  # unflipped
    _, t_raw, m_raw = make_batch(fs, idx, HEIGHT_META, np.random.default_rng(7))
    assert np.array_equal(t, t_raw) and np.array_equal(m, m_raw)  # the same flips of labels and valid pixels
    rng = np.random.default_rng(7)
    flipped = 0
    for b in range(len(idx)):
        want = x0[b, :, :40, :56]
        if rng.random() < 0.5:
            want, flipped = want[:, :, ::-1], flipped + 1
        if rng.random() < 0.5:
            want, flipped = want[:, ::-1, :], flipped + 1
        assert np.array_equal(x[b, :, :40, :56], want)
        assert not x[b, :, 40:].any() and not x[b, :, :, 56:].any()  # padding stays 0
    assert flipped > 0  # the seed flips something, so the comparison is not of unflipped frames
    assert np.array_equal(x[:, 0], x[:, 2])  # depth replicated after the flip


def test_frames_preprocessed_for_another_input_are_refused() -> None:
    ps = prepare_frames(_frames(2), HEIGHT_META)
    with pytest.raises(DataError, match="preprocessed for"):
        make_batch(ps, np.array([0]), META)


def test_training_on_preprocessed_frames_learns_and_splits_by_index(tmp_path) -> None:
    fs = _frames(32)
    tr, va = prepare_frames(fs, META, np.arange(24)), prepare_frames(fs, META, np.arange(24, 32))
    assert len(tr) == 24 and np.array_equal(tr.label, fs.label[:24]) and len(va.subset(np.arange(3))) == 3
    res = train(META, tr, va, tmp_path, TrainConfig(epochs=3, batch_size=8, lr=1e-2, seed=0, threads=1))
    assert min(h["val_loss"] for h in res.history[1:]) < res.history[0]["val_loss"]


@pytest.mark.parametrize("mode", ["once", "per-batch"])
def test_cli_preprocess_modes_train_and_are_recorded(mode, tmp_path) -> None:
    _write_tiny_mcap(tmp_path / "x")
    out = tmp_path / mode
    assert train_main(["--data", str(tmp_path / "x"), "--out", str(out), "--epochs", "1", "--width", "0.0625",
                       "--batch-size", "2", "--threads", "1", "--split", "0.5,0.5,0", "--preprocess", mode]) == 0
    assert read_checkpoint(out / "best.pt")["meta"]["training"]["preprocess"] == mode


def test_preprocessing_once_that_would_not_fit_in_memory_trains_per_batch_and_says_so(tmp_path, capsys,
                                                                                       monkeypatch) -> None:
    import edge.train.data as data

    monkeypatch.setattr(data, "available_memory_bytes", lambda: 1000)
    _write_tiny_mcap(tmp_path / "x")
    out = tmp_path / "run"
    assert train_main(["--data", str(tmp_path / "x"), "--out", str(out), "--epochs", "1", "--width", "0.0625",
                       "--batch-size", "2", "--threads", "1", "--split", "0.5,0.5,0"]) == 0
    assert "GiB available; preprocessing per batch instead" in capsys.readouterr().err
    assert read_checkpoint(out / "best.pt")["meta"]["training"]["preprocess"] == "per-batch"


def test_the_memory_check_counts_every_process_of_this_machine(monkeypatch) -> None:
    import edge.train.data as data

    one = data.prepared_bytes(100, 40, 56, 1)
    monkeypatch.setattr(data, "available_memory_bytes", lambda: data.RESERVE_BYTES + int(1.5 * one))
    assert data.preprocess_mode("once", 100, 40, 56, 1) == ("once", None)
    mode, why = data.preprocess_mode("once", 100, 40, 56, 1, copies=2)  # two torchrun ranks: 2 copies
    assert mode == "per-batch" and "2 processes on this machine" in why
    assert data.preprocess_mode("per-batch", 100, 40, 56, 1, copies=2) == ("per-batch", None)


def test_one_process_agrees_with_itself_and_reads_one_local_process(monkeypatch) -> None:
    from edge.train.distributed import Dist, local_world_size

    monkeypatch.delenv("LOCAL_WORLD_SIZE", raising=False)
    assert local_world_size() == 1 and Dist().all_agree(True) and not Dist().all_agree(False)
    monkeypatch.setenv("LOCAL_WORLD_SIZE", "4")
    assert local_world_size() == 4


def test_the_prepared_set_size_is_what_prepare_frames_allocates() -> None:
    ps = prepare_frames(_frames(3), HEIGHT_META)
    assert prepared_bytes(3, 40, 56, 1) == ps.channels.nbytes + ps.valid.nbytes + ps.label.nbytes


def test_available_memory_is_read_from_meminfo_where_there_is_one() -> None:
    from pathlib import Path

    from edge.train.data import available_memory_bytes

    got = available_memory_bytes()
    if Path("/proc/meminfo").exists():
        assert got is not None and got > 0
    else:
        assert got is None


def _windows_of(padded: np.ndarray, crop: tuple[int, int], frame: tuple[int, int] = (40, 56)):
    """Every window of a padded [C, Hp, Wp] array with the frame flipped in place: what a crop may be."""
    h, w = frame
    for lr, ud in ((False, False), (True, False), (False, True), (True, True)):
        f = padded.copy()
        f[:, :h, :w] = padded[:, :h, :w][:, ::-1 if ud else 1, ::-1 if lr else 1]
        for top in range(f.shape[1] - crop[0] + 1):
            for left in range(f.shape[2] - crop[1] + 1):
                yield f[:, top : top + crop[0], left : left + crop[1]]


def test_a_crop_is_a_window_of_the_frame_preprocessed_whole() -> None:
    fs = _frames(4, seed=5)
    idx = np.arange(4)
    ps = prepare_frames(fs, HEIGHT_META)
    x, t, m = make_batch(ps, idx, HEIGHT_META, np.random.default_rng(3), crop=(32, 32))
    assert x.shape == (4, 4, 32, 32) and t.shape == m.shape == (4, 1, 32, 32)  # a multiple of 32: no padding
    x0, t0, m0 = make_batch(ps, idx, HEIGHT_META)  # whole, unflipped frames, preprocessed whole, padded
    for b in range(4):
        got = np.concatenate([x[b], t[b], m[b]])
        frame = np.concatenate([x0[b, :, :40, :56], t0[b, :, :40, :56], m0[b, :, :40, :56]])
        padded = np.zeros((frame.shape[0], 64, 64), np.float32)  # padding at the bottom and right, as inference
        padded[:, :40, :56] = frame
        assert any(np.array_equal(got, w) for w in _windows_of(padded, (32, 32)))
    assert np.array_equal(x[:, 0], x[:, 2])  # depth still replicated
    # per-batch preprocessing (of the flipped raw frame) cuts the same windows with the same draws
    _, t_raw, m_raw = make_batch(fs, idx, HEIGHT_META, np.random.default_rng(3), crop=(32, 32))
    assert np.array_equal(t_raw, t) and np.array_equal(m_raw, m)


def test_crop_windows_reach_every_border_and_the_padding_in_about_a_quarter_of_the_draws() -> None:
    from edge.train.data import _draw_window

    rng = np.random.default_rng(0)  # the sensor's 171 x 224 frames, padded to 192 x 224 for the network
    corners = np.array([_draw_window(rng, (171, 224), (192, 224), (128, 160)) for _ in range(4000)])
    assert corners.min(axis=0).tolist() == [0, 0] and corners.max(axis=0).tolist() == [64, 64]
    for share in ((corners[:, 0] == 0).mean(), (corners[:, 0] == 64).mean(),  # top row; the whole padding band
                  (corners[:, 1] == 0).mean(), (corners[:, 1] == 64).mean()):
        assert 0.2 < share < 0.3  # uniform corners would give ~1/65
    inner = corners[:, 0][(corners[:, 0] > 0) & (corners[:, 0] < 64)]
    counts = np.bincount(inner, minlength=64)[1:]
    assert counts.min() > 0.4 * counts.mean()  # the positions between stay equally likely
    small = np.array([_draw_window(rng, (40, 56), (64, 64), (8, 8)) for _ in range(2000)])
    assert small[:, 0].max() == 39 and small[:, 1].max() == 55  # a window always holds some of the frame


def test_a_crop_without_random_draws_or_larger_than_the_frame_is_refused() -> None:
    fs = _frames(2)
    with pytest.raises(DataError, match="rng"):
        make_batch(fs, np.array([0]), META, crop=(32, 32))
    with pytest.raises(DataError, match="larger than the frames"):
        make_batch(fs, np.array([0]), META, np.random.default_rng(0), crop=(64, 32))
    with pytest.raises(DataError, match="multiples of 32"):
        make_batch(fs, np.array([0]), META, np.random.default_rng(0), crop=(32, 40))
    with pytest.raises(ConfigError, match="crop must be"):
        TrainConfig(crop=(0, 32))
    with pytest.raises(ConfigError, match="random augmentation"):
        TrainConfig(crop=(32, 32), augment=False)


def test_training_on_crops_learns_and_records_the_window(tmp_path) -> None:
    fs = _frames(32)
    tr, va = fs.subset(np.arange(24)), fs.subset(np.arange(24, 32))
    res = train(META, tr, va, tmp_path, TrainConfig(epochs=4, batch_size=8, lr=1e-2, seed=0, threads=1,
                                                     crop=(32, 32)))
    losses = [h["val_loss"] for h in res.history]  # of whole validation frames
    assert min(losses[1:]) < 0.8 * losses[0]
    assert read_checkpoint(tmp_path / "best.pt")["meta"]["training"]["config"]["crop"] in ([32, 32], (32, 32))


def test_crop_epochs_train_on_windows_first_and_whole_frames_after(tmp_path, monkeypatch) -> None:
    import edge.train.loop as loop

    seen = []
    real = loop.make_batch

    def spy(fs, idx, meta, rng=None, crop=None):
        x, t, m = real(fs, idx, meta, rng, crop=crop)
        if rng is not None:  # a training batch (validation draws nothing)
            seen.append(x.shape[-2:])
        return x, t, m

    monkeypatch.setattr(loop, "make_batch", spy)
    fs = _frames(16)
    train(META, fs.subset(np.arange(8)), fs.subset(np.arange(8, 16)), tmp_path,
          TrainConfig(epochs=3, batch_size=8, seed=0, threads=1, crop=(32, 32), crop_epochs=2))
    assert seen == [(32, 32), (32, 32), (64, 64)]  # one batch an epoch: two on windows, then the padded frame

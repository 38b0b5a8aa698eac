"""depthseg-bench: round-robin timing, report fields, torch-free, one-line errors (no timing asserts)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from onnxgen import linear_model, raw_model

from edge.bench import ModelSpec, bench_models, cpu_info, stats
from edge.errors import ConfigError
from edge.sampleframes import synthetic_frames
from export.bench_cli import main

REQUIRED = {"name", "p50_ms", "p90_ms", "p99_ms", "fps", "whole_frame_p50_ms"}


@pytest.fixture(scope="module")
def models(tmp_path_factory):
    d = tmp_path_factory.mktemp("bench")
    return linear_model(d / "plain.onnx"), raw_model(d / "raw.onnx")


def test_stats_are_percentiles_of_the_runs():
    s = stats(list(range(1, 101)))
    assert s["min"] == 1 and s["max"] == 100 and s["mean"] == 50.5
    assert s["p50"] == pytest.approx(50.5) and s["p90"] == pytest.approx(90.1) and s["p99"] == pytest.approx(99.01)


def test_bench_models_interleaves_and_reports_every_stage(models):
    plain, raw = models
    specs = [ModelSpec(plain, threads=1), ModelSpec(raw, name="raw", threads=1)]
    rounds = []
    res = bench_models(specs, synthetic_frames(2).depth, runs=7, warmup=1, on_round=rounds.append)
    assert rounds == list(range(7))
    assert [r["name"] for r in res] == ["plain", "raw"]
    for r in res:
        assert REQUIRED <= set(r) and r["runs"] == 7 and r["threads"] == 1 and r["precision"] == "fp32"
        t = r["timings"]
        assert set(t) == {"whole", "pre", "infer", "post"}
        for s in t.values():
            assert s["min"] <= s["p50"] <= s["p90"] <= s["p99"] <= s["max"]
        assert r["p50_ms"] == t["infer"]["p50"] and r["whole_frame_p50_ms"] == t["whole"]["p50"]
        assert r["whole_frame_p50_ms"] >= t["infer"]["min"]  # the whole frame contains the inference
        assert r["fps"] == pytest.approx(1000.0 / t["whole"]["mean"])
        assert r["load_ms"] > 0 and r["first_run_ms"] > 0 and r["size_mb"] > 0
    assert res[0]["ratio_to_first"] == 1.0
    assert res[1]["ratio_to_first"] == pytest.approx(res[1]["whole_frame_p50_ms"] / res[0]["whole_frame_p50_ms"])
    assert res[1]["graph"] == "with-preprocessing" and res[0]["graph"] == "logits"


def test_bench_models_refuses_nothing_to_do(models):
    with pytest.raises(ConfigError):
        bench_models([], synthetic_frames(1).depth)
    with pytest.raises(ConfigError):
        bench_models([ModelSpec(models[0])], synthetic_frames(1).depth, runs=0)


def test_cpu_info_names_the_cpu_and_its_isa():
    info = cpu_info()
    assert info["model"] and info["logical_cpus"] >= 1 and info["usable_cpus"] >= 1
    assert isinstance(info["isa"], list)


def test_cli_table_lists_every_model(models, capsys):
    rc = main(["--model", str(models[0]), str(models[1]), "--threads", "1", "--runs", "3", "--warmup", "1", "--frames", "2"])
    out = capsys.readouterr().out
    assert rc == 0
    assert "intra-op threads 1, inter-op 1, sequential" in out and "frame p50" in out and "x first" in out
    assert "plain" in out and "raw" in out and "CPU:" in out


def test_cli_json(models, capsys):
    rc = main(["--model", str(models[0]), str(models[1]), "--threads", "1", "--runs", "4", "--warmup", "1", "--json"])
    assert rc == 0
    res = json.loads(capsys.readouterr().out)
    assert [m["name"] for m in res["models"]] == ["plain", "raw"]
    for m in res["models"]:
        assert REQUIRED <= set(m) and all(np.isfinite(m[k]) and m[k] > 0 for k in REQUIRED - {"name"})
    assert res["threads"] == 1 and res["inter_op_threads"] == 1 and res["runtime"]["onnxruntime"]
    assert res["cpu"]["model"] and "synthetic" in res["frames"] and res["peak_rss_mb"] > 0


@pytest.mark.parametrize("kind", ["missing", "corrupt"])
def test_bad_model_is_one_line_and_nonzero(tmp_path, kind):
    path = tmp_path / "m.onnx"
    if kind == "corrupt":
        path.write_bytes(b"definitely not onnx")
    proc = subprocess.run([sys.executable, "-m", "export.bench_cli", "--model", str(path), "--runs", "2"],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2
    err = proc.stderr.strip()
    assert len(err.splitlines()) == 1 and err.startswith("depthseg-bench: error:") and "m.onnx" in err
    assert "Traceback" not in err and proc.stdout == ""


def test_torch_option_times_pytorch_eager_too(models, capsys):
    pytest.importorskip("torch")
    rc = main(["--model", str(models[0]), "--threads", "1", "--runs", "2", "--warmup", "1", "--torch", "--json"])
    assert rc == 0
    (m,) = json.loads(capsys.readouterr().out)["models"]
    assert m["torch_whole_frame_p50_ms"] > 0 and m["torch_p50_ms"] > 0 and m["torch_threads"] == 1


@pytest.mark.slow
def test_compare_adds_a_random_init_architecture(models, capsys):
    pytest.importorskip("torch")
    rc = main(["--model", str(models[0]), "--compare", "vgg11_bn:0.125", "--threads", "1", "--runs", "2",
               "--warmup", "1", "--json"])
    assert rc == 0, capsys.readouterr().err
    res = json.loads(capsys.readouterr().out)
    a, b = res["models"]
    assert b["name"].startswith("vgg11_bn w0.125") and b["weights"] == "random-init" and b["in_channels"] == 3
    assert b["ratio_to_first"] == pytest.approx(b["whole_frame_p50_ms"] / a["whole_frame_p50_ms"])


def test_compare_exports_in_process_and_adds_the_model(models, tiny_onnx, monkeypatch, capsys):
    """The --compare plumbing (the real export of a random-init architecture is the slow test above)."""
    import shutil

    import export.api

    calls = []

    def fake_export(encoder, out, width=1.0, **kw):
        calls.append((encoder, width))
        return Path(shutil.copy(tiny_onnx, out))

    monkeypatch.setattr(export.api, "export_random", fake_export)
    rc = main(["--model", str(models[0]), "--compare", "vgg13:0.25", "--threads", "1", "--runs", "2",
               "--warmup", "1", "--json"])
    assert rc == 0, capsys.readouterr().err
    a, b = json.loads(capsys.readouterr().out)["models"]
    assert calls == [("vgg13", 0.25)] and b["name"].startswith("vgg13 w0.25")
    assert b["ratio_to_first"] == pytest.approx(b["whole_frame_p50_ms"] / a["whole_frame_p50_ms"])
    assert main(["--model", str(models[0]), "--compare", "vgg13:x"]) == 2
    assert "--compare" in capsys.readouterr().err


def test_bench_models_times_turns_of_block_frames(models, monkeypatch):
    # each model runs `block` frames in a row, the first model of a turn rotates, every model gets every run
    from edge.infer import Segmenter

    plain, raw = models
    specs = [ModelSpec(plain, threads=1), ModelSpec(raw, name="raw", threads=1)]
    calls: list[str] = []
    original = Segmenter.predict

    def predict(self, depth, threshold=None):
        calls.append(self.name)
        return original(self, depth, threshold)

    monkeypatch.setattr(Segmenter, "predict", predict)
    for block in (1, 3):
        calls.clear()
        rounds = []
        bench_models(specs, synthetic_frames(2).depth, runs=5, warmup=0, on_round=rounds.append, block=block)
        timed = [Path(c).stem for c in calls[2:]]  # after one first run per model
        assert rounds == list(range(5))
        if block == 1:
            assert timed == ["plain", "raw", "raw", "plain", "plain", "raw", "raw", "plain", "plain", "raw"]
        else:
            assert timed == ["plain"] * 3 + ["raw"] * 3 + ["raw"] * 2 + ["plain"] * 2
    with pytest.raises(ConfigError, match="block"):
        bench_models(specs, synthetic_frames(1).depth, runs=2, block=0)


def test_cli_times_every_model_at_each_thread_count(models, capsys):
    rc = main(["--model", str(models[0]), "--threads", "1", "2", "--runs", "2", "--warmup", "1", "--json"])
    assert rc == 0, capsys.readouterr().err
    res = json.loads(capsys.readouterr().out)
    assert [(m["name"], m["threads"]) for m in res["models"]] == [("plain t1", 1), ("plain t2", 2)]
    assert res["threads"] == [1, 2] and res["block"] == 10
    assert main(["--model", str(models[0]), "--threads", "2", "2"]) == 2  # counts must be distinct
    assert "distinct" in capsys.readouterr().err


def test_rate_paces_the_timed_frames_like_a_sensor(models, monkeypatch):
    # with --rate the timed frames start 1/rate s apart (a sensor's period), whatever each one takes
    from edge import bench
    from edge.infer import Segmenter

    plain, _raw = models
    starts: list[float] = []
    original = Segmenter.predict

    def predict(self, depth, threshold=None):
        starts.append(bench.time.perf_counter())
        return original(self, depth, threshold)

    monkeypatch.setattr(Segmenter, "predict", predict)
    res = bench_models([ModelSpec(plain, threads=1)], synthetic_frames(2).depth, runs=6, warmup=0, rate=50.0)
    gaps = np.diff(starts[1:])  # after the untimed first run
    assert len(gaps) == 5 and gaps.min() >= 0.02 - 1e-4  # 50 Hz: 20 ms between frame starts
    assert res[0]["rate_hz"] == 50.0
    starts.clear()
    assert bench_models([ModelSpec(plain, threads=1)], synthetic_frames(2).depth, runs=3, warmup=0)[0]["rate_hz"] is None
    for bad in (-1.0, float("nan"), float("inf")):
        with pytest.raises(ConfigError, match="rate"):
            bench_models([ModelSpec(plain, threads=1)], synthetic_frames(1).depth, runs=2, rate=bad)


def test_cli_rate_is_reported_and_a_negative_rate_is_one_line(models, capsys):
    rc = main(["--model", str(models[0]), "--runs", "2", "--warmup", "0", "--rate", "100", "--json"])
    assert rc == 0, capsys.readouterr().err
    assert json.loads(capsys.readouterr().out)["rate_hz"] == 100.0
    assert main(["--model", str(models[0]), "--runs", "2", "--rate", "100"]) == 0
    assert "paced at 100 frames/s" in capsys.readouterr().out
    assert main(["--model", str(models[0]), "--rate", "-5"]) == 2
    err = capsys.readouterr().err
    assert "rate" in err and "Traceback" not in err and len(err.strip().splitlines()) == 1

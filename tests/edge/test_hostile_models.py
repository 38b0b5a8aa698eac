"""Issue 11, models and commands: hostile or damaged model files, missing extras, unsafe paths.

Every bad input must end in one line on stderr, exit code 2, no traceback, and no file written
or destroyed. Fast: hand-built ONNX models (`onnxgen`) and tiny recordings; torch only where a
``.pt`` is the point (skipped without it).
"""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path

import numpy as np
import pytest
from onnxgen import linear_model
from replaygen import scene

from edge.errors import ModelError
from edge.io import FrameWriter
from edge.meta import ModelMeta

pytestmark = pytest.mark.filterwarnings("ignore::DeprecationWarning")


@pytest.fixture(scope="module")
def rec(tmp_path_factory) -> Path:
    """A labelled recording of 4 small frames."""
    path = tmp_path_factory.mktemp("hostile") / "rec.mcap"
    with FrameWriter(path) as w:
        for i in range(4):
            depth, lab = scene(i)
            w.write(1_000_000 * (i + 1), depth, lab)
    return path


@pytest.fixture(scope="module")
def good_onnx(tmp_path_factory) -> Path:
    return linear_model(tmp_path_factory.mktemp("hostile_onnx") / "m.onnx", k=4.0)


def _with_props(src: Path, dst: Path, **props: str) -> Path:
    """A copy of ``src`` with some ``metadata_props`` replaced (the graph untouched)."""
    import onnx

    m = onnx.load(str(src))
    kv = {e.key: e.value for e in m.metadata_props}
    kv.update(props)
    del m.metadata_props[:]
    for k, v in kv.items():
        m.metadata_props.append(onnx.StringStringEntryProto(key=k, value=v))
    onnx.save(m, str(dst))
    return dst


def _meta_json(**changes) -> str:
    d = ModelMeta(encoder="vgg11", width=0.125, batch_norm=True, in_channels=1).to_dict()
    for k, v in changes.items():
        if k.startswith("sensor_"):
            d["sensor"][k[len("sensor_"):]] = v
        else:
            d[k] = v
    return json.dumps(d)


def _one_line_error(capsys, rc: int, prog: str) -> str:
    out, err = capsys.readouterr()
    assert rc == 2, err
    assert err.count("\n") == 1 and err.startswith(f"{prog}: error:"), err
    assert "Traceback" not in err
    return err


def _eval(*argv) -> int:
    from edge.eval_cli import main

    return main([str(a) for a in argv])


def _tune(*argv) -> int:
    from edge.tune_cli import main

    return main([str(a) for a in argv])


# ------------------------------------------------------------------ 1. metadata by type and range

BAD_META = [
    ({"threshold": "abc"}, "'threshold' = 'abc'"),
    ({"threshold": float("nan")}, "'threshold' = nan"),
    ({"threshold": 7}, "'threshold' = 7"),
    ({"threshold": True}, "'threshold' = True"),
    ({"threshold": 10**400}, "'threshold' = 1000000"),  # an int beyond a float: not an OverflowError
    ({"sensor_fx": -(10**400)}, "'sensor.fx' = -1000000"),
    ({"pad_multiple": 1.5}, "'pad_multiple' = 1.5"),
    ({"pad_multiple": 65536}, "'pad_multiple' = 65536"),
    ({"pad_multiple": 0}, "'pad_multiple' = 0"),
    ({"in_channels": 2}, "'in_channels' = 2"),
    ({"in_channels": "3"}, "'in_channels' = '3'"),
    ({"width": 1e9}, "'width' = 1000000000.0"),
    ({"batch_norm": "no"}, "'batch_norm' = 'no'"),
    ({"cues": "height"}, "'cues' = 'height'"),
    ({"standardize": 5}, "'standardize' = 5"),
    ({"sensor_width": -5}, "'sensor.width' = -5"),
    ({"sensor_height": 10**12}, "'sensor.height' = 1000000000000"),
    ({"sensor_fx": "abc"}, "'sensor.fx' = 'abc'"),
    ({"sensor_distortion": [1.0, "k2", 0.0]}, "'sensor.distortion' = 'k2'"),
    ({"sensor_min_range_m": 5.0}, "'sensor.min_range_m' = 5.0"),
    ({"training": [1, 2]}, "'training' = [1, 2]"),
    ({"version": 99}, "'version' = 99"),
    ({"sensor": "pico"}, "'sensor' = 'pico'"),
]


@pytest.mark.parametrize("changes, needle", BAD_META)
def test_bad_metadata_values_are_one_model_error_naming_key_and_value(changes, needle):
    with pytest.raises(ModelError) as exc:
        ModelMeta.from_json(_meta_json(**changes))
    assert needle in str(exc.value) and "\n" not in str(exc.value)


@pytest.mark.parametrize(
    "text, needle",
    [
        ("[" * 200_000 + "]" * 200_000, "nested too deeply"),
        (_meta_json(training=json.loads("{\"a\":" * 60 + "1" + "}" * 60)), "nested deeper than"),
        ('{"threshold": ' + "9" * 5000 + "}", "not valid JSON"),
        ('{"threshold": 1e400}', "'threshold' = inf"),
        ("NaN", "must be a JSON object"),
        ("", "not valid JSON"),
    ],
)
def test_malformed_metadata_json_is_one_model_error(text, needle):
    with pytest.raises(ModelError, match=needle):
        ModelMeta.from_json(text)


@pytest.mark.parametrize(
    "changes, needle",
    [({"threshold": "abc"}, "'threshold' = 'abc'"), ({"pad_multiple": 65536}, "'pad_multiple' = 65536"),
     ({"pad_multiple": 1.5}, "'pad_multiple' = 1.5")],
)
def test_eval_tune_bench_refuse_an_onnx_with_bad_metadata_in_one_line(capsys, tmp_path, rec, good_onnx, changes, needle):
    bad = _with_props(good_onnx, tmp_path / "bad.onnx", depthseg=_meta_json(**changes))
    err = _one_line_error(capsys, _eval("--model", bad, "--data", rec), "depthseg-eval")
    assert needle in err and str(bad) in err
    err = _one_line_error(capsys, _tune("--model", bad, "--data", rec, "--dry-run"), "depthseg-tune")
    assert needle in err
    from export.bench_cli import main as bench

    err = _one_line_error(capsys, bench(["--model", str(bad), "--runs", "1", "--warmup", "0"]), "depthseg-bench")
    assert needle in err


def test_deeply_nested_onnx_metadata_is_one_line(capsys, tmp_path, rec, good_onnx):
    bad = _with_props(good_onnx, tmp_path / "deep.onnx", depthseg="[" * 100_000 + "]" * 100_000)
    err = _one_line_error(capsys, _eval("--model", bad, "--data", rec), "depthseg-eval")
    assert "nested too deeply" in err


def _checkpoint(path: Path, **blob) -> Path:
    torch = pytest.importorskip("torch")
    torch.save({"format": "depthseg-checkpoint", "version": 1, **blob}, path)
    return path


@pytest.mark.parametrize(
    "blob, needle",
    [
        ({"meta": {"threshold": "abc"}, "state_dict": {}}, "'threshold' = 'abc'"),
        ({"meta": {"pad_multiple": 65536}, "state_dict": {}}, "'pad_multiple' = 65536"),
        ({"meta": {"sensor": {"width": 1.5}}, "state_dict": {}}, "'sensor.width' = 1.5"),
        ({"state_dict": {}}, "no 'meta' record"),
        ({"meta": [], "state_dict": {}}, "no 'meta' record"),
        ({"meta": {}, "state_dict": 5}, "no 'state_dict'"),
        ({"meta": {"encoder": "resnet"}, "state_dict": {}}, "unknown encoder 'resnet'"),
        ({"meta": {"encoder": "vgg11", "width": 0.125}, "state_dict": {"x": 1}}, "do not match"),
    ],
)
def test_checkpoint_with_bad_metadata_is_one_line(capsys, tmp_path, rec, blob, needle):
    pt = _checkpoint(tmp_path / "bad.pt", **blob)
    err = _one_line_error(capsys, _eval("--model", pt, "--data", rec), "depthseg-eval")
    assert needle in err


# ------------------------------------------------------------------ 2. NaN / infinite logits


@pytest.mark.parametrize("bias", [float("nan"), float("inf")])
def test_non_finite_logits_are_an_error_naming_the_model_not_no_objects(capsys, tmp_path, rec, bias):
    from edge.infer import Segmenter

    broken = linear_model(tmp_path / "broken.onnx", bias=bias)
    with pytest.raises(ModelError, match="non-finite logits"):
        Segmenter(broken, threads=1).predict(scene(0)[0])
    err = _one_line_error(capsys, _eval("--model", broken, "--data", rec), "depthseg-eval")
    assert str(broken) in err and "non-finite logits" in err
    err = _one_line_error(capsys, _tune("--model", broken, "--data", rec, "--dry-run", "--split", "0"), "depthseg-tune")
    assert str(broken) in err and "non-finite logits" in err


def test_a_predictor_returning_nan_fails_evaluate_and_tune():
    from edge.evaluate import evaluate
    from edge.io import Frame
    from edge.tune import tune

    class NaNModel:
        meta = ModelMeta()
        name = "nan-model"

        def logits(self, depth):
            out = np.zeros(depth.shape, np.float32)
            out[3, 4] = np.nan
            return out

    depth, lab = scene(0)
    with pytest.raises(ModelError, match="nan-model: .*1 NaN"):
        evaluate(NaNModel(), [Frame(depth=depth, stamp_ns=1, label=lab)])
    with pytest.raises(ModelError, match="nan-model: .*1 NaN"):
        tune(NaNModel(), [Frame(depth=depth, stamp_ns=1, label=lab)], split=0)


# ------------------------------------------------------------------ 4. missing extras


def test_eval_without_model_uses_the_shipped_onnx_and_needs_no_torch(capsys, monkeypatch, tmp_path, rec, good_onnx):
    from edge import defaults

    monkeypatch.setattr(defaults, "DEFAULT_ONNX", good_onnx)
    monkeypatch.setattr(defaults, "DEFAULT_CHECKPOINT", tmp_path / "default.pt")
    (tmp_path / "default.pt").write_bytes(b"present, but eval must not need it")
    monkeypatch.setitem(sys.modules, "torch", None)
    assert _eval("--data", rec, "--json") == 0
    assert json.loads(capsys.readouterr().out)["model"] == str(good_onnx)


@pytest.mark.parametrize(
    "blocked, argv, needle",
    [
        ("torch", ("eval", "--model", "{pt}", "--data", "{rec}"), "torch not installed for the checkpoint"),
        ("open3d", ("eval", "--model", "{onnx}", "--data", "{rec}", "--baseline"), "depthseg[sim]"),
        ("torch", ("tune", "--model", "{pt}", "--data", "{rec}", "--dry-run"), "depthseg[train]"),
        ("onnx", ("tune", "--model", "{onnx}", "--data", "{rec}", "--out", "{tmp}/o.onnx"), "onnx not installed"),
        ("matplotlib", ("tune", "--model", "{onnx}", "--data", "{rec}", "--dry-run", "--plot", "{tmp}/p.png"),
         "matplotlib not installed"),
        ("open3d", ("tune", "--model", "{onnx}", "--data", "{rec}", "--dry-run", "--pseudo-labels"), "depthseg[sim]"),
        ("torch", ("train", "--data", "{rec}", "--out", "{tmp}/run"), "depthseg[train]"),
        ("torch", ("export", "--out", "{tmp}/x.onnx", "--random-init"), "depthseg[train]"),
        ("onnxscript", ("bench", "--model", "{onnx}", "--compare", "vgg11"), "onnxscript not installed"),
        ("torch", ("bench", "--model", "{onnx}", "--torch"), "depthseg[train]"),
    ],
)
def test_a_missing_extra_is_one_line_naming_it(capsys, monkeypatch, tmp_path, rec, good_onnx, blocked, argv, needle):
    import edge.eval_cli
    import edge.train_cli
    import edge.tune_cli
    import export.bench_cli
    import export.cli

    mains = {"eval": edge.eval_cli.main, "tune": edge.tune_cli.main, "train": edge.train_cli.main,
             "export": export.cli.main, "bench": export.bench_cli.main}
    pt = tmp_path / "m.pt"
    pt.write_bytes(b"x")  # never opened: the extra is checked first
    fill = {"pt": pt, "rec": rec, "onnx": good_onnx, "tmp": tmp_path}
    monkeypatch.setitem(sys.modules, blocked, None)
    rc = mains[argv[0]]([a.format(**fill) for a in argv[1:]])
    err = _one_line_error(capsys, rc, f"depthseg-{argv[0]}")
    assert needle in err and "pip install 'depthseg[" in err
    assert not (tmp_path / "o.onnx").exists() and not (tmp_path / "run").exists()


# ------------------------------------------------------------------ 5. paths


def test_eval_figures_naming_a_file_is_one_line(capsys, tmp_path, rec, good_onnx):
    f = tmp_path / "figs"
    f.write_text("mine")
    err = _one_line_error(capsys, _eval("--model", good_onnx, "--data", rec, "--figures", f), "depthseg-eval")
    assert "--figures" in err and "not a directory" in err and f.read_text() == "mine"


@pytest.mark.parametrize("which", ["out=model", "plot=data", "plot=model", "out=data"])
def test_tune_never_writes_over_its_inputs(capsys, tmp_path, rec, good_onnx, which):
    import shutil

    model = Path(shutil.copy(good_onnx, tmp_path / "m.onnx"))
    data = Path(shutil.copy(rec, tmp_path / "d.onnx" if which == "out=data" else tmp_path / "d.mcap"))
    before = model.read_bytes(), data.read_bytes()
    flag, target = which.split("=")
    argv = ["--model", model, "--data", data, f"--{flag}", model if target == "model" else data]
    err = _one_line_error(capsys, _tune(*argv), "depthseg-tune")
    assert f"--{flag}" in err and "would overwrite the input" in err
    assert (model.read_bytes(), data.read_bytes()) == before


def test_fifos_as_inputs_are_refused_not_waited_on(capsys, tmp_path, rec, good_onnx):
    from export.bench_cli import main as bench
    from export.cli import main as export

    fifo = tmp_path / "m.onnx"
    os.mkfifo(fifo)
    err = _one_line_error(capsys, _eval("--model", fifo, "--data", rec), "depthseg-eval")
    assert "FIFO" in err and "--model" in err
    _one_line_error(capsys, _tune("--model", fifo, "--data", rec, "--dry-run"), "depthseg-tune")
    _one_line_error(capsys, bench(["--model", str(fifo)]), "depthseg-bench")
    err = _one_line_error(capsys, bench(["--model", str(good_onnx), "--data", str(fifo)]), "depthseg-bench")
    assert "--data" in err and "FIFO" in err
    fifo_pt = tmp_path / "m.pt"
    os.mkfifo(fifo_pt)
    _one_line_error(capsys, export(["--model", str(fifo_pt), "--out", str(tmp_path / "x.onnx")]), "depthseg-export")
    _one_line_error(capsys, _eval("--model", good_onnx, "--data", fifo), "depthseg-eval")


def test_export_out_never_an_input(capsys, tmp_path, rec):
    from export.cli import main as export

    pt = tmp_path / "m.pt"
    pt.write_bytes(b"my checkpoint")
    err = _one_line_error(capsys, export(["--model", str(pt), "--out", str(pt)]), "depthseg-export")
    assert "--out" in err and "would overwrite the input --model" in err
    data = tmp_path / "d.onnx"
    data.write_bytes(b"my data")
    err = _one_line_error(capsys, export(["--random-init", "--data", str(data), "--out", str(data)]), "depthseg-export")
    assert "would overwrite the input --data" in err
    assert pt.read_bytes() == b"my checkpoint" and data.read_bytes() == b"my data"


@pytest.mark.parametrize("tool", ["bench", "export"])
def test_damaged_data_is_one_line(capsys, tmp_path, rec, good_onnx, tool):
    from export.bench_cli import main as bench
    from export.cli import main as export

    cut = tmp_path / "cut.mcap"
    cut.write_bytes(rec.read_bytes()[: len(rec.read_bytes()) // 3])
    junk = tmp_path / "junk.mcap"
    junk.write_bytes(b"\x89MCAP0\r\n" + bytes(range(256)) * 4)
    for bad in (cut, junk):
        if tool == "bench":
            rc = bench(["--model", str(good_onnx), "--data", str(bad), "--runs", "1", "--warmup", "0"])
        else:
            pytest.importorskip("torch")
            rc = export(["--random-init", "--encoder", "vgg11", "--width", "0.125", "--data", str(bad),
                         "--out", str(tmp_path / "x.onnx")])
        _one_line_error(capsys, rc, f"depthseg-{tool}")
    assert not (tmp_path / "x.onnx").exists()


@pytest.mark.parametrize("case", ["out=data dir", "out inside data", "out is a file", "resume fifo"])
def test_train_run_dir_is_checked_before_any_work(capsys, tmp_path, rec, case):
    import shutil

    from edge.train_cli import main as train

    data = tmp_path / "data"
    data.mkdir()
    shutil.copy(rec, data / "rec.mcap")
    out = {"out=data dir": data, "out inside data": data / "run", "out is a file": data / "rec.mcap",
           "resume fifo": tmp_path / "run"}[case]
    argv = ["--data", str(data), "--out", str(out)]
    if case == "resume fifo":
        out.mkdir()
        os.mkfifo(out / "last.pt")
        argv.append("--resume")
    err = _one_line_error(capsys, train(argv), "depthseg-train")
    assert "--out" in err or "--resume" in err
    assert sorted(p.name for p in data.iterdir()) == ["rec.mcap"]


# ------------------------------------------------------------------ 6. code in a .pt


class _CreatesAFile:
    """Unpickling this calls open(path, "w"): the file appears if unpickling runs code."""

    def __init__(self, path: str) -> None:
        self.path = path

    def __reduce__(self):
        return (open, (self.path, "w"))


@pytest.mark.parametrize("tool", ["eval", "tune", "export"])
@pytest.mark.filterwarnings("ignore:Detected pickle protocol")
@pytest.mark.parametrize("fmt", ["torch.save", "raw pickle"])
def test_a_pt_whose_unpickling_creates_a_file_does_not_create_it(capsys, tmp_path, rec, tool, fmt):
    import pickle

    torch = pytest.importorskip("torch")
    from export.cli import main as export

    target = tmp_path / "pwned"
    evil = tmp_path / "evil.pt"
    payload = {"format": "depthseg-checkpoint", "meta": {}, "state_dict": {}, "x": _CreatesAFile(str(target))}
    if fmt == "torch.save":
        torch.save(payload, evil)
    else:
        evil.write_bytes(pickle.dumps(payload))
    assert not target.exists()
    if tool == "eval":
        rc = _eval("--model", evil, "--data", rec)
    elif tool == "tune":
        rc = _tune("--model", evil, "--data", rec, "--dry-run")
    else:
        rc = export(["--model", str(evil), "--out", str(tmp_path / "x.onnx")])
    err = _one_line_error(capsys, rc, f"depthseg-{tool}")
    assert "not a readable depthseg checkpoint" in err
    assert not target.exists()


def test_every_torch_load_in_the_code_base_is_weights_only():
    root = Path(__file__).resolve().parents[2]
    calls = []
    for pkg in ("edge", "export", "replay", "sim", "tools"):
        for py in (root / pkg).rglob("*.py"):
            for n, line in enumerate(py.read_text().splitlines(), 1):
                if "torch.load(" in line:
                    calls.append((py.relative_to(root), n, line))
    assert calls, "expected the checkpoint loaders"
    unsafe = [c for c in calls if "weights_only=True" not in c[2]]
    assert not unsafe, unsafe


# ------------------------------------------------------------------ 7. bench --compare in-process


def test_bench_compare_never_spawns_a_process(capsys, monkeypatch, tmp_path, good_onnx):
    import shutil
    import subprocess

    import export.api
    from export.bench_cli import main as bench

    real_popen = subprocess.Popen

    class NoPython(real_popen):  # platform.processor() may run `uname -p`: that is fine
        def __init__(self, args, *a, **k):
            text = " ".join(map(str, args)) if isinstance(args, (list, tuple)) else str(args)
            if "python" in text or sys.executable in text or "export.cli" in text:
                raise AssertionError(f"depthseg-bench started a Python process: {text}")
            super().__init__(args, *a, **k)

    monkeypatch.setattr(subprocess, "Popen", NoPython)
    monkeypatch.setattr(export.api, "export_random",
                        lambda encoder, out, width=1.0, **kw: Path(shutil.copy(good_onnx, out)))
    rc = bench(["--model", str(good_onnx), "--compare", "vgg11:0.125", "--threads", "1", "--runs", "2",
                "--warmup", "0", "--json"])
    assert rc == 0, capsys.readouterr().err
    assert len(json.loads(capsys.readouterr().out)["models"]) == 2


def test_tune_never_rewrites_a_model_inside_the_installed_package(capsys, monkeypatch, tmp_path, rec, good_onnx):
    import shutil

    import edge.io.paths

    pkg = tmp_path / "site-packages" / "edge"
    pkg.mkdir(parents=True)
    model = Path(shutil.copy(good_onnx, pkg / "other.onnx"))
    before = model.read_bytes()
    monkeypatch.setattr(edge.io.paths, "package_roots", lambda: [pkg])
    err = _one_line_error(capsys, _tune("--model", model, "--data", rec, "--split", "0"), "depthseg-tune")
    assert "installed depthseg package" in err
    assert model.read_bytes() == before and not list(pkg.glob("*.bak"))

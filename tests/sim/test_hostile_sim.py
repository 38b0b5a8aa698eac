"""Hostile and careless input to ``depthseg-sim`` and ``depthseg-sim import`` (issue 11).

Every bad input: one line on stderr, exit 2, no traceback, nothing written, no work done first.
"""

from __future__ import annotations

import json
import os
import threading
import time
import tracemalloc
from pathlib import Path

import pytest

from edge.errors import ConfigError, DataError
from sim import cli
from sim import dataset as sim_dataset
from sim import importers as imp
from sim.generate import SimConfig


def _one_line(capsys, rc: int, needle: str, prog: str = "depthseg-sim") -> str:
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert rc == 2, err
    assert len(lines) == 1 and lines[0].startswith(f"{prog}: error:"), err
    assert needle in lines[0] and "Traceback" not in err, lines[0]
    return lines[0]


# ----------------------------------------------------------------------------- config values by type


@pytest.mark.parametrize(
    "config, needle",
    [
        ({"sensor": {"mixed_pixels": "no"}}, "sensor.mixed_pixels must be true or false"),
        ({"sensor": {"flying_filter": 0}}, "sensor.flying_filter must be true or false"),
        ({"supersample_edges": "false"}, "config.supersample_edges must be true or false"),
        ({"scene": {"n_objects": "05"}}, "scene.n_objects must be a list of 2 numbers, got '05'"),
        ({"scene": {"n_objects": [0, 5, 9]}}, "scene.n_objects must be a list of 2 numbers"),
        ({"scene": {"camera_height_m": ["0.2", "0.4"]}}, "scene.camera_height_m[0] must be a finite number"),
        ({"scene": {"largest_dim_m": [0.04, float("nan")]}}, "scene.largest_dim_m[1] must be a finite number"),
        ({"scene": {"drop_step_m": True}}, "scene.drop_step_m must be a finite number"),
        ({"scene": {"shapes": "box"}}, "scene.shapes must be a list of strings"),
        ({"scene": {"views_per_scene": "2"}}, "scene.views_per_scene must be a whole number"),
        ({"physics": {"rest_checks": "2"}}, "physics.rest_checks must be a whole number"),
        ({"physics": {"friction": [1, "a", 2]}}, "physics.friction[1] must be a finite number"),
        ({"camera": {"fx": float("nan")}}, "camera.fx must be a finite number"),
        ({"camera": {"cy": float("inf")}}, "camera.cy must be a finite number"),
        ({"camera": {"width": "224"}}, "camera.width must be a whole number"),
        ({"camera": {"width": 100_000, "height": 100_000}}, "above the simulator's limit"),
        ({"camera": {"distortion": "abcde"}}, "camera.distortion must be a list of numbers"),
        ({"render_threads": "4"}, "config.render_threads must be a whole number"),
        ({"render_threads": 0}, "config.render_threads = 0 is outside"),
        ({"intrinsics_to": [200, 200, 100, float("inf")]}, "config.intrinsics_to[3] must be a finite number"),
        ({"scene": {"scene": {"n_objects": [1, 2]}}}, "unknown scene keys ['scene']"),
        ({"n_objects": [1, 2]}, "unknown config sections ['n_objects']"),
        ({"camera": [1]}, "config section 'camera' must be an object"),
    ],
)
def test_config_values_are_checked_by_type(config, needle):
    with pytest.raises(ConfigError) as info:
        SimConfig.from_dict(config)
    assert needle in str(info.value) and "\n" not in str(info.value)


def test_valid_configs_keep_their_meaning_and_digest():
    """Ints where floats are expected, lists for tuples, JSON booleans: accepted as before."""
    c = SimConfig.from_dict({"scene": {"n_objects": [1, 3], "drop_step_m": 1}, "sensor": {"mixed_pixels": False},
                             "render_threads": 2, "camera": {"fx": 200}})
    assert c.sensor.mixed_pixels is False and c.scene.n_objects == (1, 3) and c.render_threads == 2
    assert SimConfig.from_dict(c.to_dict()).digest() == c.digest()
    assert SimConfig.from_dict(None).digest() == SimConfig().digest()


# ----------------------------------------------------------------------------- --config files


def _deep(n: int) -> str:
    return "[" * n + "]" * n


@pytest.mark.parametrize(
    "content, needle",
    [
        (b"\x89PNG\r\n\x1a\n\x00\xff\xfe", "not a UTF-8 text file"),
        ("[1, 2]", "must hold a JSON object"),
        ('"scene"', "must hold a JSON object"),
        ("", "not valid JSON"),
        (_deep(100_000), "nested too deeply"),
        ('{"camera": {"fx": NaN}}', "camera.fx must be a finite number"),
        ('{"camera": {"cx": Infinity}}', "camera.cx must be a finite number"),
        ('{"render_threads": "4"}', "config.render_threads must be a whole number"),
        ('{"scene": {"drop_step_m": ' + "9" * 5000 + "}}", "number too long"),
        (" " * (cli.MAX_CONFIG_BYTES + 1), "too large for a simulator config"),
    ],
)
def test_hostile_config_file_is_one_line(tmp_path, capsys, content, needle):
    p = tmp_path / "cfg.json"
    p.write_bytes(content if isinstance(content, bytes) else content.encode())
    out = tmp_path / "o"
    _one_line(capsys, cli.main(["--out", str(out), "--frames", "1", "--config", str(p)]), needle)
    assert not out.exists()


def test_config_fifo_or_directory_is_refused_without_blocking(tmp_path, capsys):
    fifo = tmp_path / "cfg.fifo"
    os.mkfifo(fifo)
    _one_line(capsys, cli.main(["--out", str(tmp_path / "o"), "--frames", "1", "--config", str(fifo)]), "--config")
    _one_line(capsys, cli.main(["--out", str(tmp_path / "o"), "--frames", "1", "--config", str(tmp_path)]),
              "is a directory")


# ----------------------------------------------------------------------------- size, workers, outputs


def _fake_workers(monkeypatch) -> list[tuple[int, int]]:
    """Shards are 'written' instantly: these tests are about planning, not frames."""
    done: list[tuple[int, int]] = []

    def write(task):
        done.append(task)
        (sim_dataset._W["out"] / sim_dataset.shard_name(*task)).write_bytes(b"")
        return {"file": sim_dataset.shard_name(*task), "frames": task[1] - task[0], "object_pixels": 0,
                "invalid_pixels": 0, "pixels": 1, "seconds": 0.0}

    monkeypatch.setattr(sim_dataset, "_init_worker", lambda c, s, lib, out, q, pooled=True: sim_dataset._W.update(out=Path(out)))
    monkeypatch.setattr(sim_dataset, "_write_shard", write)
    return done


def test_frames_beyond_the_limits_are_refused_before_any_work(tmp_path, capsys):
    out = tmp_path / "o"
    t0 = time.perf_counter()
    _one_line(capsys, cli.main(["--out", str(out), "--frames", str(10**12)]), "above the limit of 99999999 frames")
    _one_line(capsys, cli.main(["--out", str(out), "--frames", "50000000", "--shard-frames", "1"]),
              "raise --shard-frames to at least 500")
    _one_line(capsys, cli.main(["--out", str(out), "--frames", "-5"]), "--frames must be at least 1")
    _one_line(capsys, cli.main(["--out", str(out), "--frames", "1", "--seed", "9" * 100]), "--seed must be below 2**128")
    _one_line(capsys, cli.main(["--out", "", "--frames", "1"]), "--out is empty")
    assert time.perf_counter() - t0 < 5 and not out.exists()


def test_planning_is_not_proportional_to_frames(tmp_path, monkeypatch):
    """The largest dataset, one array job of two shards: nothing is built per shard of the whole plan."""
    done = _fake_workers(monkeypatch)
    tracemalloc.start()
    try:
        s = sim_dataset.simulate(tmp_path / "o", sim_dataset.MAX_FRAMES, shard_frames=1000, workers=1,
                                 frames_range=(0, 2000), show_progress=False)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert done == [(0, 1000), (1000, 2000)] and s["shards"] == 2
    assert peak < 4_000_000, peak  # a list of the 100,000 planned shards alone would be ~10 MB


def test_workers_capped_at_usable_cores(tmp_path, monkeypatch, capsys):
    _fake_workers(monkeypatch)
    monkeypatch.setattr(sim_dataset, "usable_cores", lambda: 1)
    rc = cli.main(["--out", str(tmp_path / "o"), "--frames", "2", "--workers", "6", "--json"])
    cap = capsys.readouterr()
    assert rc == 0, cap.err
    assert [ln for ln in cap.err.splitlines() if "warning" in ln] == [
        "depthseg-sim: warning: --workers 6 capped at the 1 usable cores"
    ]
    assert json.loads(cap.out)["workers"] == 1


def test_missing_extra_is_named_at_start(tmp_path, monkeypatch, capsys):
    import importlib.util

    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec", lambda name, *a: None if name == "mujoco" else real(name, *a))
    _one_line(capsys, cli.main(["--out", str(tmp_path / "o"), "--frames", "1"]), "pip install 'depthseg[sim]'")
    assert not (tmp_path / "o").exists()


def test_pool_worker_that_cannot_import_open3d_fails_fast(tmp_path, monkeypatch, capsys):
    """multiprocessing.Pool replaces a worker whose initializer raises, forever: ours fail their first task."""
    fake = tmp_path / "fake" / "open3d"
    fake.mkdir(parents=True)
    (fake / "__init__.py").write_text('raise ImportError("libusb-1.0.so.0: cannot open shared object file", name="open3d")\n')
    monkeypatch.syspath_prepend(str(tmp_path / "fake"))  # spawned workers get this sys.path; we never import it
    monkeypatch.setattr(sim_dataset, "usable_cores", lambda: 2)
    result: list[int] = []
    th = threading.Thread(target=lambda: result.append(cli.main(
        ["--out", str(tmp_path / "o"), "--frames", "2", "--shard-frames", "1", "--workers", "2"])), daemon=True)
    th.start()
    th.join(120)
    assert result, "the pool kept respawning its workers"
    _one_line(capsys, result[0], "a worker cannot import open3d")


def test_out_never_replaces_an_input(tmp_path, capsys):
    lib = tmp_path / "meshes"
    lib.mkdir()
    _one_line(capsys, cli.main(["--out", str(lib / "o"), "--frames", "1", "--objects", str(lib)]),
              "would overwrite the input --objects")
    cap = tmp_path / "cap.mcap"
    cap.write_bytes(b"ply\n")
    rc = imp.import_main(["ply", str(cap), "--out", str(cap)])
    _one_line(capsys, rc, "would overwrite the input", prog="depthseg-sim import ply")
    assert cap.read_bytes() == b"ply\n"


def test_unreachable_ray_address_is_refused_in_seconds():
    from sim.ray_runner import check_address

    t0 = time.perf_counter()
    with pytest.raises(ConfigError, match="no Ray cluster answers there"):
        check_address("127.0.0.1:1")
    with pytest.raises(ConfigError, match="no host name"):
        check_address("ray://:10001")
    with pytest.raises(ConfigError, match="outside 1-65535"):
        check_address("head:99999")
    assert time.perf_counter() - t0 < 10


# ----------------------------------------------------------------------------- PLY import

_HEAD = "ply\nformat ascii 1.0\n"
_VERT = "element vertex 192\nproperty float x\nproperty float y\nproperty float z\n"
_ROW = "0.01 0.02 0.3\n"


def _ply(tmp_path: Path, text: str | bytes) -> Path:
    p = tmp_path / "cap.ply"
    p.write_bytes(text if isinstance(text, bytes) else text.encode())
    return p


@pytest.mark.parametrize(
    "body, needle",
    [
        (_ROW * 100 + "0.01 0.02\n" + _ROW * 92, "line 108 (vertex 100) holds 2 values; the header declares 3"),
        (_ROW * 100 + "0.01 0.02 0.3 9\n" + _ROW * 92, "line 108 (vertex 100) holds 4 values"),
        (_ROW * 100 + "\n" + _ROW * 92, "line 108 (vertex 100) holds 0 values"),
        (_ROW * 191 + "0 " * 10_000 + "\n", "is longer than 256 bytes"),
    ],
)
def test_ply_rows_are_checked_against_the_header(tmp_path, body, needle):
    with pytest.raises(DataError) as info:
        imp.read_ply(_ply(tmp_path, _HEAD + _VERT + "end_header\n" + body), width=16, height=12)
    assert needle in str(info.value) and "\n" not in str(info.value)


def test_huge_element_before_the_vertices_is_refused_at_once(tmp_path):
    t0 = time.perf_counter()
    for count in (10**18, 10**8):
        text = _HEAD + f"element junk {count}\nproperty float a\n" + _VERT + "end_header\n" + _ROW * 192
        with pytest.raises(DataError, match="more than the .* bytes left in the file can hold"):
            imp.read_ply(_ply(tmp_path, text), width=16, height=12)
    assert time.perf_counter() - t0 < 2


def test_element_before_the_vertices_is_skipped_by_its_rows(tmp_path):
    text = _HEAD + "element junk 3\nproperty float a\n" + _VERT + "end_header\n" + "1\n2\n3\n" + _ROW * 192
    cap = imp.read_ply(_ply(tmp_path, text), width=16, height=12)
    assert cap.points.shape == (12, 16, 3) and float(cap.points[0, 0, 2]) == pytest.approx(0.3)


def test_ply_header_is_bounded(tmp_path):
    text = _HEAD + "comment " + "x" * (1 << 20) + "\n" + _VERT + "end_header\n" + _ROW * 192
    with pytest.raises(DataError, match="header is longer than"):
        imp.read_ply(_ply(tmp_path, text), width=16, height=12)


def test_ply_fifo_input_is_refused_without_blocking(tmp_path, capsys):
    fifo = tmp_path / "cap.ply"
    os.mkfifo(fifo)
    rc = imp.import_main(["ply", str(fifo), "--out", str(tmp_path / "o.mcap")])
    _one_line(capsys, rc, "is a FIFO", prog="depthseg-sim import ply")
    with pytest.raises(DataError, match="is a FIFO"):
        imp.read_ply(fifo)


# ----------------------------------------------------------------------------- --objects meshes


def test_mesh_header_declaring_more_than_the_file_holds_is_skipped(tmp_path):
    """open3d sizes arrays from the header: a 30-byte OFF declaring 2e8 vertices took 3.8 GB."""
    from sim.shapes import MeshLibrary

    (tmp_path / "a.off").write_text("OFF\n200000000 1 0\n0 0 0\n")
    (tmp_path / "b.ply").write_text("ply\nformat ascii 1.0\nelement vertex 40000000\nproperty float x\n"
                                    "property float y\nproperty float z\nend_header\n0 0 0\n")
    (tmp_path / "c.stl").write_bytes(b"\0" * 80 + (10**9).to_bytes(4, "little") + b"\0" * 50)
    skipped: list[str] = []
    with pytest.raises(ConfigError, match="none of the 3 mesh files"):
        MeshLibrary.scan(tmp_path, on_skip=lambda p, reason: skipped.append(reason))
    assert len(skipped) == 3 and all("more vertices or faces than its" in r for r in skipped)


def test_blensor_scan_with_a_huge_declared_shape_asks_for_no_memory(tmp_path):
    import numpy as np

    p = tmp_path / "scan_0.npy"
    with open(p, "wb") as f:
        np.lib.format.write_array_header_1_0(f, {"descr": "<f8", "fortran_order": False, "shape": (2, 10**10)})
        f.write(b"\0" * 100)
    with pytest.raises(DataError, match="shorter than its header declares"):
        imp.read_blensor_scan(p)

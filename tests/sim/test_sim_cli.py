"""depthseg-sim end to end: MCAP any tool can read, one-line errors, mesh warnings, --json."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

import edge.io as fr
from sim import cli
from sim import dataset as sim_dataset

TINY = {"scene": {"n_objects": [1, 3]}}


def _config(tmp_path: Path, d: dict) -> str:
    p = tmp_path / "cfg.json"
    p.write_text(json.dumps(d))
    return str(p)


@pytest.fixture(scope="module")
def dataset(tmp_path_factory) -> tuple[Path, dict]:
    tmp = tmp_path_factory.mktemp("sim")
    out = tmp / "out"
    summary = sim_dataset.simulate(out, frames=5, seed=4, workers=1, shard_frames=3, config=None, show_progress=False)
    return out, summary


def test_summary_and_shards(dataset):
    out, s = dataset
    assert s["frames"] == 5 and s["generated"] == 5 and s["shards"] == 2
    assert s["frames_per_second"] > 0 and 0 < s["object_pixel_fraction"] < 1
    assert sorted(p.name for p in out.glob("*.mcap")) == ["frames_00000000_00000003.mcap", "frames_00000003_00000005.mcap"]
    m = json.loads((out / "manifest.json").read_text())
    assert m["seed"] == 4 and m["frames"] == 5 and len(m["shards"]) == 2 and m["summary"]["frames"] == 5
    from edge.provenance import provenance

    assert m["provenance"] == provenance()  # version and git commit that wrote the data set


def test_simulator_output_opens_in_rosbags_anyreader(dataset):
    """rosbags reads a simulator shard as a ROS 2 bag: every message decodes, stamps are not 1970."""
    AnyReader = pytest.importorskip("rosbags.highlevel").AnyReader

    out, _ = dataset
    with AnyReader([out / "frames_00000000_00000003.mcap"]) as r:
        topics = {c.topic for c in r.connections}
        assert {fr.TOPIC_DEPTH, fr.TOPIC_LABELS, fr.TOPIC_INFO, fr.TOPIC_SCENE} <= topics
        n = 0
        for conn, t, raw in r.messages():
            msg = r.deserialize(raw, conn.msgtype)
            n += 1
            if conn.topic == fr.TOPIC_SCENE:
                assert json.loads(msg.data)["seed"] == [4, json.loads(msg.data)["index"]]
            else:
                assert msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec == t >= fr.SIM_EPOCH_NS
                assert msg.header.stamp.sec >= 1_704_067_200  # 2024-01-01, not 1970
        assert n == 15


def test_output_opens_with_mcap_and_decodes_with_mcap_ros2(dataset):
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    out, _ = dataset
    seen: dict[str, int] = {}
    with open(out / "frames_00000000_00000003.mcap", "rb") as fh:
        reader = make_reader(fh, decoder_factories=[DecoderFactory()])
        assert reader.get_header().profile == "ros2"
        for schema, channel, message in reader.iter_messages():
            seen[channel.topic] = seen.get(channel.topic, 0) + 1
            if channel.topic == fr.TOPIC_SCENE:
                assert schema.name == "std_msgs/msg/String" and channel.message_encoding == "cdr"
                scene = fr.decode_scene(channel.message_encoding, message.data)
                assert scene["seed"] == [4, scene["index"]]
                continue
            msg = DecoderFactory().decoder_for(channel.message_encoding, schema)(message.data)
            if channel.topic == fr.TOPIC_DEPTH:
                assert (msg.height, msg.width, msg.encoding) == (171, 224, "32FC1")
                depth = np.frombuffer(bytes(msg.data), dtype="<f4").reshape(171, 224)
                assert (depth == 0).any() and 0.1 < depth.max() < 1.0  # metres, 0 = invalid
            elif channel.topic == fr.TOPIC_LABELS:
                assert msg.encoding == "mono8"
                assert set(np.unique(np.frombuffer(bytes(msg.data), np.uint8))) <= {0, 1}
            elif channel.topic == fr.TOPIC_INFO:
                assert msg.k[0] == pytest.approx(112 / np.tan(np.radians(31)), rel=1e-6)
                assert msg.header.frame_id == fr.FRAME_ID
    assert seen == {t: 3 for t in (fr.TOPIC_DEPTH, fr.TOPIC_LABELS, fr.TOPIC_INFO, fr.TOPIC_CLEAN, fr.TOPIC_SCENE)}


def test_shards_equal_frames_regenerated_alone(dataset):
    from sim.generate import generate_frame

    out, _ = dataset
    frames = list(fr.iter_frames(out, with_clean=True))
    assert [f.stamp_ns for f in frames] == [fr.SIM_EPOCH_NS + i * 22_222_222 for i in range(5)]  # 2024, not 1970
    again = generate_frame(4, 4)
    np.testing.assert_array_equal(frames[4].depth, again.depth)
    np.testing.assert_array_equal(frames[4].label, again.label)
    np.testing.assert_array_equal(frames[4].clean, again.clean)


def _fails(capsys, argv: list[str], needle: str) -> None:
    rc = cli.main(argv)
    err = capsys.readouterr().err
    assert rc == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("depthseg-sim: error:"), err
    assert needle in lines[0] and "Traceback" not in err


def test_bad_input_gives_one_line_errors(tmp_path, capsys):
    out = str(tmp_path / "o")
    _fails(capsys, ["--out", out, "--frames", "0"], "--frames must be at least 1")
    _fails(capsys, ["--out", out, "--frames", "2", "--objects", str(tmp_path / "nope")], "no such folder")
    (tmp_path / "empty").mkdir()
    _fails(capsys, ["--out", out, "--frames", "2", "--objects", str(tmp_path / "empty")], "no .obj/.stl/.off/.ply")
    bad = _config(tmp_path, {"scene": {"largest_dim_m": [0.1, 0.04]}})
    _fails(capsys, ["--out", out, "--frames", "2", "--config", bad], "min 0.1 is above max 0.04")
    (tmp_path / "file").write_text("x")
    _fails(capsys, ["--out", str(tmp_path / "file" / "sub"), "--frames", "2"], "choose a writable path")
    _fails(capsys, ["--out", str(tmp_path / "file"), "--frames", "2"], "not a directory")
    _fails(capsys, ["--out", out, "--frames", "2", "--config", str(tmp_path / "none.json")], "no such file")
    _fails(capsys, ["--out", out, "--frames", "2", "--workers", "0"], "--workers must be at least 1")


def test_resume_with_other_options_is_refused(dataset, capsys):
    out, _ = dataset
    _fails(capsys, ["--out", str(out), "--frames", "5", "--seed", "5", "--shard-frames", "3"], "different seed")


def test_resume_under_another_physics_version_is_refused(dataset, tmp_path, capsys):
    import shutil

    out, _ = dataset
    m = json.loads((out / "manifest.json").read_text())
    assert m["engines"] == sim_dataset.engines() and set(m["engines"]) == {"mujoco", "open3d", "numpy", "scipy"}
    copy = tmp_path / "copy"
    shutil.copytree(out, copy)
    m["engines"]["mujoco"] = "0.0.1"  # as if the frames had been made by another mujoco
    (copy / "manifest.json").write_text(json.dumps(m))
    now = sim_dataset.engines()["mujoco"]
    _fails(capsys, ["--out", str(copy), "--frames", "5", "--seed", "4", "--shard-frames", "3"],
           f"made with mujoco 0.0.1, this is mujoco {now}, and its frames would differ; resume with pip install "
           "'mujoco==0.0.1' or choose another --out")
    assert sorted(p.name for p in copy.iterdir()) == sorted(p.name for p in out.iterdir())  # nothing touched
    for unusable in ("4.0.0", None):  # garbage where the versions belong, or none: says nothing, resumes
        m["engines"] = unusable
        (copy / "manifest.json").write_text(json.dumps(m))
        assert cli.main(["--out", str(copy), "--frames", "5", "--seed", "4", "--shard-frames", "3"]) == 0
    del m["engines"]  # a manifest from before versions were recorded resumes as before
    (copy / "manifest.json").write_text(json.dumps(m))
    assert cli.main(["--out", str(copy), "--frames", "5", "--seed", "4", "--shard-frames", "3"]) == 0


def test_mesh_library_run_warns_once_per_bad_mesh(tmp_path, capsys):
    import open3d as o3d

    lib = tmp_path / "meshes"
    lib.mkdir()
    o3d.io.write_triangle_mesh(str(lib / "box.obj"), o3d.geometry.TriangleMesh.create_box(1, 2, 3))
    (lib / "broken.ply").write_text("ply\nformat ascii 1.0\nelement vertex 3\nend_header\n1 2\n")
    cfg = _config(tmp_path, TINY)
    rc = cli.main(["--out", str(tmp_path / "o"), "--frames", "2", "--workers", "1", "--objects", str(lib), "--config", cfg, "--json"])
    cap = capsys.readouterr()
    assert rc == 0, cap.err
    warnings = [ln for ln in cap.err.splitlines() if "warning" in ln]
    assert len(warnings) == 1 and "broken.ply" in warnings[0]
    summary = json.loads(cap.out)
    assert summary["frames"] == 2 and summary["frames_per_second"] > 0 and summary["objects_skipped"] == 1
    shapes = {o["shape"] for f in fr.iter_frames(tmp_path / "o") for o in f.scene["params"]["objects"]}
    assert shapes == {"mesh"}


def test_import_subcommand_is_dispatched(monkeypatch):
    import sim.importers

    got = []
    monkeypatch.setattr(sim.importers, "import_main", lambda argv: got.append(argv) or 7)
    assert cli.main(["import", "blensor", "x"]) == 7
    assert got == [["blensor", "x"]]

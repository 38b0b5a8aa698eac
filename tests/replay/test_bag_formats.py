"""One recording as MCAP, ROS 1 .bag, ROS 2 .db3 and ROS 2 bag directory gives the same masks.

The bags are converted from the MCAP inside the test with ``rosbags`` (ROS 1 messages through
its typestore's CDR -> ROS 1 conversion), so the only difference between the four inputs is the
container. A compressedDepth recording (16-bit PNG with the transport's 12-byte header) works
and gives the masks of the raw 16UC1 recording.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from mcap.writer import Writer
from replaygen import PERIOD, T0, FakeSegmenter, scene, write_ros2

from edge import rosmsg
from edge.cliutil import run
from edge.errors import McapDataError
from edge.io.compressed import encode_compressed_depth
from edge.io.reader import open_depth_stream
from replay.replay import replay

pytest.importorskip("rosbags")
from rosbags.convert.converter import convert  # noqa: E402
from rosbags.typesys import Stores, get_typestore  # noqa: E402


def _convert(src: Path, dst: Path) -> Path:
    """``rosbags-convert`` as a function: MCAP (ROS 2) -> ROS 1 .bag, or -> a ROS 2 sqlite3 bag directory."""
    convert([src], dst, "sqlite3", 9, None, "file", get_typestore(Stores.ROS2_HUMBLE), None, [], [], [], [])
    return dst


def to_ros1(src: Path, dst: Path) -> Path:
    return _convert(src, dst)


def to_ros2(src: Path, dst: Path) -> Path:
    return _convert(src, dst)


def masks_of(path: Path) -> tuple[list[np.ndarray], list, object]:
    stream = open_depth_stream(path)
    masks: list[np.ndarray] = []
    labels: list = []
    s = replay(stream, FakeSegmenter(), on_frame=lambda r: (masks.append(r.mask.copy()), labels.append(r.frame.label)))
    return masks, labels, (stream, s)


@pytest.mark.parametrize("invalid", ["zero", "nan"])
def test_mcap_ros1_db3_and_bag_dir_give_identical_masks(tmp_path, invalid):
    rec = write_ros2(tmp_path / "rec.mcap", n=6, invalid=invalid)
    ros1 = to_ros1(rec.path, tmp_path / "rec.bag")
    ros2dir = to_ros2(rec.path, tmp_path / "rec_ros2")
    db3 = next(ros2dir.glob("*.db3"))
    ref, ref_labels, (ref_stream, ref_sum) = masks_of(rec.path)
    assert len(ref) == 6 and all(lab is not None for lab in ref_labels)
    assert (np.concatenate(ref) == 255).any() and (np.concatenate(ref) == 1).any()
    for path in (ros1, ros2dir, db3):
        masks, labels, (stream, s) = masks_of(path)
        assert (stream.depth_topic, stream.labels_topic, stream.info_topic) == (
            ref_stream.depth_topic, ref_stream.labels_topic, ref_stream.info_topic), path
        assert stream.camera_info == ref_stream.camera_info
        assert len(masks) == len(ref)
        for a, b in zip(masks, ref):
            np.testing.assert_array_equal(a, b)
        for a, b in zip(labels, ref_labels):
            np.testing.assert_array_equal(a, b)
        assert s.metrics.iou == ref_sum.metrics.iou


def recompress_ros1(src: Path, dst: Path, compression: str, chunk_threshold: int | None = None) -> Path:
    """A ROS 1 bag rewritten by rosbags' writer with bz2 or lz4 chunks (message bytes unchanged)."""
    from rosbags.rosbag1 import Reader, Writer

    w = Writer(dst)
    w.set_compression(Writer.CompressionFormat.BZ2 if compression == "bz2" else Writer.CompressionFormat.LZ4)
    if chunk_threshold is not None:
        w.chunk_threshold = chunk_threshold
    with Reader(src) as r, w:
        conns = {
            c.id: w.add_connection(c.topic, c.msgtype, msgdef=c.msgdef.data, md5sum=c.digest,
                                   callerid=c.ext.callerid, latching=c.ext.latching)
            for c in r.connections
        }
        for c, t, raw in r.messages():
            w.write(conns[c.id], t, raw)
    return dst


@pytest.mark.parametrize("compression", ["bz2", "lz4"])
def test_compressed_ros1_bags_pass_the_chunk_check_and_give_the_same_masks(tmp_path, compression):
    """The bounded pre-pass over a ROS 1 bag's chunks (`_check_ros1_chunks`) accepts honest chunks,
    several of them (a small chunk threshold), and the masks are those of the MCAP."""
    rec = write_ros2(tmp_path / "rec.mcap", n=5)
    ros1 = to_ros1(rec.path, tmp_path / "rec.bag")
    packed = recompress_ros1(ros1, tmp_path / f"rec_{compression}.bag", compression, chunk_threshold=4096)
    assert packed.read_bytes().count(f"compression={compression}".encode()) > 1
    ref, _, _ = masks_of(rec.path)
    masks, _, _ = masks_of(packed)
    assert len(masks) == len(ref) == 5
    for a, b in zip(masks, ref):
        np.testing.assert_array_equal(a, b)


def test_bag_errors_are_the_same_one_liners(tmp_path):
    rec = write_ros2(tmp_path / "rec.mcap", n=2, labels=False)
    ros1 = to_ros1(rec.path, tmp_path / "rec.bag")
    for path in (rec.path, ros1):
        with pytest.raises(McapDataError, match=r"no depth topic '/nope'; image topics: /pico_flexx/image_depth \(sensor_msgs/msg/Image, 32FC1"):
            open_depth_stream(path, topic="/nope")
    bad = tmp_path / "broken.bag"
    bad.write_bytes(b"#ROSBAG V2.0\n" + b"\x00" * 40)
    with pytest.raises(McapDataError, match=r"broken.bag: unreadable ROS 1 bag") as ei:
        open_depth_stream(bad)
    assert "\n" not in str(ei.value)
    plain = tmp_path / "plain"
    plain.mkdir()
    with pytest.raises(McapDataError, match=r"without metadata.yaml"):
        open_depth_stream(plain)


def test_replay_cli_reads_a_db3_bag_directory(tmp_path, linear_onnx, capsys):
    rec = write_ros2(tmp_path / "rec.mcap", n=4)
    ros2dir = to_ros2(rec.path, tmp_path / "bagdir")
    from replay.cli import main

    assert main([str(ros2dir), "--model", str(linear_onnx), "--json", "--out", str(tmp_path / "o.mcap")]) == 0
    assert '"frames": 4' in capsys.readouterr().out
    assert run("x", lambda: main([str(tmp_path / "nope.db3"), "--model", str(linear_onnx)])) == 2


def _write_compressed(path: Path, n: int = 5) -> list[np.ndarray]:
    """compressedDepth 16UC1 png, as compressed_depth_image_transport publishes it."""
    depths = []
    with open(path, "wb") as fh:
        w = Writer(fh)
        w.start(profile="ros2", library="test")
        sid = w.register_schema(
            "sensor_msgs/msg/CompressedImage", "ros2msg",
            b"std_msgs/Header header\nstring format\nuint8[] data\n"
            b"================================================================================\n"
            b"MSG: std_msgs/Header\nbuiltin_interfaces/Time stamp\nstring frame_id\n"
            b"================================================================================\n"
            b"MSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec\n",
        )
        ch = w.register_channel("/camera/depth/image_raw/compressedDepth", "cdr", sid)
        for i in range(n):
            d, _ = scene(i)
            mm = np.round(d * 1000).astype(np.uint16)
            depths.append(mm)
            t = T0 + i * PERIOD
            w.add_message(ch, t, encode_compressed_depth(t, "cam", mm), t)
        w.finish()
    return depths


def test_compressed_depth_recording_replays_like_raw_16uc1(tmp_path):
    mm = _write_compressed(tmp_path / "cd.mcap")
    stream = open_depth_stream(tmp_path / "cd.mcap")
    assert stream.depth_topic == "/camera/depth/image_raw/compressedDepth"
    assert stream.depth_encoding == "16UC1"
    got = [fr.depth for fr in stream]
    assert len(got) == len(mm)
    for a, b in zip(got, mm):
        np.testing.assert_allclose(a, b.astype(np.float32) / 1000, rtol=0, atol=1e-6)
        assert ((a == 0) == (b == 0)).all()  # invalid pixels stay invalid
    # the same frames as plain 16UC1 Image messages give the same masks
    raw = tmp_path / "raw.mcap"
    with open(raw, "wb") as fh:
        w = Writer(fh)
        w.start(profile="ros2", library="test")
        sid = w.register_schema(rosmsg.IMAGE_TYPE, "ros2msg", rosmsg.IMAGE_MSGDEF.encode())
        ch = w.register_channel("/camera/depth/image_raw", "cdr", sid)
        for i, m in enumerate(mm):
            t = T0 + i * PERIOD
            w.add_message(ch, t, rosmsg.encode_image(t, "cam", m, "16UC1"), t)
        w.finish()
    a, _, _ = masks_of(tmp_path / "cd.mcap")
    b, _, _ = masks_of(raw)
    for x, y in zip(a, b):
        np.testing.assert_array_equal(x, y)
    # and inside a ROS 1 bag
    c, _, _ = masks_of(to_ros1(tmp_path / "cd.mcap", tmp_path / "cd.bag"))
    for x, y in zip(c, b):
        np.testing.assert_array_equal(x, y)


def test_replay_outputs_open_in_rosbags_anyreader(tmp_path):
    """--out of a ROS 2 recording (with an old-style JSON channel) and of a ROS 1 bag are ROS 2 files."""
    from rosbags.highlevel import AnyReader

    src = tmp_path / "in.mcap"
    with open(src, "wb") as fh:
        w = Writer(fh)
        w.start(profile="ros2", library="test")
        sid = w.register_schema(rosmsg.IMAGE_TYPE, "ros2msg", rosmsg.IMAGE_MSGDEF.encode())
        js = w.register_schema("depthseg/Scene", "jsonschema", b"{}")
        ch = w.register_channel("/pico_flexx/image_depth", "cdr", sid)
        jch = w.register_channel("/depthseg/scene", "json", js)
        for i in range(3):
            t = T0 + i * PERIOD
            w.add_message(ch, t, rosmsg.encode_image(t, "cam", scene(i)[0], "32FC1"), t)
            w.add_message(jch, t, b'{"index": %d}' % i, t)
        w.finish()
    outs = []
    bag = to_ros1(write_ros2(tmp_path / "plain.mcap", n=3, labels=False, info=False).path, tmp_path / "in.bag")
    for path in (src, bag):
        out = tmp_path / f"out_{path.suffix[1:]}.mcap"
        replay(open_depth_stream(path), FakeSegmenter(), out=out, out_namespace="/seg")
        outs.append(out)
    for out in outs:
        with AnyReader([out]) as r:
            types = {c.topic: c.msgtype for c in r.connections}
            assert types["/seg/mask"] == types["/seg/mask_raw"] == types["/seg/overlay"] == "sensor_msgs/msg/Image"
            assert types.get("/depthseg/scene", "std_msgs/msg/String") == "std_msgs/msg/String"
            seen: dict[str, int] = {}
            for conn, t, raw in r.messages():
                msg = r.deserialize(raw, conn.msgtype)
                seen[conn.topic] = seen.get(conn.topic, 0) + 1
                if conn.topic == "/seg/mask":
                    assert msg.encoding == "rgb8" and msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec == t
                if conn.topic == "/depthseg/scene":
                    assert msg.data.startswith('{"index": ')
            assert {k: v for k, v in seen.items() if k != "/depthseg/scene"} == {
                "/pico_flexx/image_depth": 3, "/seg/mask": 3, "/seg/mask_raw": 3, "/seg/overlay": 3}
            if out == outs[0]:  # the JSON scene of the input, copied as std_msgs/String
                assert seen["/depthseg/scene"] == 3


def test_training_loads_labelled_frames_from_bags(tmp_path):
    """depthseg-train/eval/tune data: a labelled .bag, .db3 or bag directory is read like the MCAP."""
    from edge.io import list_mcap_files
    from edge.train.data import load_frames

    rec = write_ros2(tmp_path / "rec.mcap", n=4)
    bag = to_ros1(rec.path, tmp_path / "bags" / "a.bag") if (tmp_path / "bags").mkdir() is None else None
    d2 = to_ros2(rec.path, tmp_path / "bags" / "b")
    assert list_mcap_files(tmp_path / "bags") == [bag, d2]
    for src in (rec.path, bag, d2, next(d2.glob("*.db3"))):
        fs = load_frames([src])
        assert len(fs) == 4
        np.testing.assert_array_equal(fs.label, np.stack(rec.label))
        np.testing.assert_array_equal(fs.depth, np.stack(rec.depth))

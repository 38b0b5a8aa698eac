"""Damaged and hostile inputs: every case is one McapDataError line naming the problem.

Truncated and corrupt files are read up to the damage (the frames before it are intact and
delivered), then the error says where it broke. Each case runs for each reader the issue names:
ROS 2 32FC1 with 0-invalid and NaN-invalid, 16UC1, foxglove RawImage in protobuf and in JSON.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap.writer import Writer
from replaygen import KINDS, SHARED, scene, write_foxglove, write_kind, write_ros2

from edge import rosmsg
from edge.errors import McapDataError
from edge.io.reader import open_depth_stream

N = 8


def read_until_error(path: Path, **kw) -> tuple[list, McapDataError | None]:
    frames = []
    try:
        for fr in open_depth_stream(path, **kw):
            frames.append(fr)
    except McapDataError as exc:
        return frames, exc
    return frames, None


def one_line(exc: BaseException) -> str:
    msg = str(exc)
    assert "\n" not in msg and len(msg) < 600, msg
    return msg


def assert_prefix_intact(frames, rec) -> None:
    for i, fr in enumerate(frames):
        assert fr.extra["index"] == i
        assert np.array_equal(fr.depth, rec.depth[i], equal_nan=True)


def chunk_spans(path: Path) -> list[tuple[int, int]]:
    with open(path, "rb") as fh:
        s = make_reader(fh).get_summary()
    return [(c.chunk_start_offset, c.chunk_length) for c in s.chunk_indexes]


@pytest.mark.parametrize("kind", KINDS)
def test_truncated_file_is_read_up_to_the_cut(kind, tmp_path):
    rec = write_kind(kind, tmp_path / "full.mcap", n=N)
    data = rec.path.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: len(data) // 2])
    frames, err = read_until_error(cut)
    assert err is not None
    msg = one_line(err)
    assert "damaged at byte" in msg and "truncated" in msg, msg
    assert 0 < len(frames) < N
    assert f"{len(frames)} depth frames were read" in msg or "depth frames were read" in msg
    assert_prefix_intact(frames, rec)


@pytest.mark.parametrize("kind", KINDS)
def test_flipped_bytes_inside_a_chunk(kind, tmp_path):
    rec = write_kind(kind, tmp_path / "full.mcap", n=N)
    data = bytearray(rec.path.read_bytes())
    spans = chunk_spans(rec.path)
    start, length = spans[len(spans) // 2]
    mid = start + length // 2
    for k in range(8):
        data[mid + k] ^= 0xFF
    bad = tmp_path / "flip.mcap"
    bad.write_bytes(bytes(data))
    frames, err = read_until_error(bad)
    assert err is not None
    msg = one_line(err)
    assert "damaged at byte" in msg and ("corrupt" in msg or "unreadable" in msg), msg
    assert 0 < len(frames) < N
    assert_prefix_intact(frames, rec)


@pytest.mark.parametrize("kind", KINDS)
def test_corrupt_record_length(kind, tmp_path):
    rec = write_kind(kind, tmp_path / "full.mcap", n=N)
    data = bytearray(rec.path.read_bytes())
    spans = chunk_spans(rec.path)
    start, _ = spans[len(spans) // 2]
    data[start + 1 + 7] = 0x7F  # most significant byte of the chunk's u64 length
    bad = tmp_path / "len.mcap"
    bad.write_bytes(bytes(data))
    frames, err = read_until_error(bad)
    assert err is not None
    assert "record length exceeds the file" in one_line(err)
    assert 0 < len(frames) < N
    assert_prefix_intact(frames, rec)


@pytest.mark.parametrize("kind", KINDS)
def test_data_size_not_height_times_step(kind, tmp_path):
    bad = 3
    if kind.startswith("fox"):
        rec = write_foxglove(tmp_path / "m.mcap", n=N, fmt="protobuf" if kind == "fox_proto" else "json", bad_step_frame=bad)
    else:
        enc = "16UC1" if kind == "ros16" else "32FC1"
        rec = write_ros2(tmp_path / "m.mcap", n=N, encoding=enc, invalid="nan" if kind == "ros32_nan" else "zero", corrupt_frame=bad)
    frames, err = read_until_error(rec.path)
    assert err is not None
    msg = one_line(err)
    assert "height x step" in msg and "malformed" in msg and rec.topic in msg and "message 3" in msg, msg
    assert len(frames) == bad  # the frames before it were delivered
    assert_prefix_intact(frames, rec)


@pytest.mark.parametrize("kind", KINDS)
def test_unknown_pixel_encoding(kind, tmp_path):
    kw = {"encoding": "weird8"}
    if kind == "ros32_nan":
        kw["invalid"] = "nan"
    if kind.startswith("ros"):
        rec = write_ros2(tmp_path / "u.mcap", n=3, **kw)
    else:
        rec = write_foxglove(tmp_path / "u.mcap", n=3, fmt="protobuf" if kind == "fox_proto" else "json", **kw)
    with pytest.raises(McapDataError) as e:
        open_depth_stream(rec.path)
    msg = one_line(e.value)
    assert "no depth image topic" in msg and "weird8" in msg and rec.topic in msg, msg
    frames, err = read_until_error(rec.path, topic=rec.topic)
    assert frames == [] and err is not None
    assert "unknown pixel encoding 'weird8'" in one_line(err)


def test_non_depth_encoding_with_topic_is_refused(tmp_path):
    d, lab = scene(0)
    rec = write_ros2(tmp_path / "a.mcap", n=2, extra={"/cam/rgb": ("rgb8", np.zeros((24, 32, 3), np.uint8))})
    _, err = read_until_error(rec.path, topic="/cam/rgb")
    assert "'rgb8' is not a depth image" in one_line(err)


def _raw_file(path: Path, schema: tuple[str, str, bytes] | None, msg_encoding: str, payloads: list[bytes],
              topic: str = "/cam/depth") -> Path:
    with open(path, "wb") as fh:
        w = Writer(fh)
        w.start(profile="", library="test")
        sid = w.register_schema(*schema) if schema else 0
        ch = w.register_channel(topic, msg_encoding, sid)
        for i, p in enumerate(payloads):
            w.add_message(ch, 1000 + i, p, 1000 + i)
        w.finish()
    return path


@pytest.mark.parametrize("kind", KINDS)
def test_undecodable_messages(kind, tmp_path):
    """What cannot be decoded is named: a foreign message encoding (ROS), a schema that is no
    FileDescriptorSet (protobuf), a payload that is not JSON (JSON)."""
    d, _ = scene(0)
    img_schema = (rosmsg.IMAGE_TYPE, "ros2msg", rosmsg.IMAGE_MSGDEF.encode())
    if kind.startswith("ros"):
        enc = "16UC1" if kind == "ros16" else "32FC1"
        arr = (d * 1000).astype(np.uint16) if enc == "16UC1" else d
        p = _raw_file(tmp_path / "w.mcap", img_schema, "wrong_format", [rosmsg.encode_image(1, "c", arr, enc)])
        expect = "message encoding 'wrong_format' cannot be decoded"
    elif kind == "fox_proto":
        p = _raw_file(tmp_path / "w.mcap", ("foxglove.RawImage", "protobuf", b"\xff\x00garbage"), "protobuf", [b"\x00"])
        expect = "protobuf schema 'foxglove.RawImage' cannot be loaded"
    else:
        from replaygen import RAW_JSON_SCHEMA

        p = _raw_file(tmp_path / "w.mcap", ("foxglove.RawImage", "jsonschema", RAW_JSON_SCHEMA), "json", [b"{not json"])
        expect = "not a foxglove RawImage JSON message"
    frames, err = read_until_error(p, topic="/cam/depth")
    assert frames == [] and err is not None
    assert expect in one_line(err), str(err)
    with pytest.raises(McapDataError) as e:  # auto-detection: nothing usable, topic listed
        open_depth_stream(p)
    assert "/cam/depth" in one_line(e.value)


def test_json_payload_missing_fields(tmp_path):
    from replaygen import RAW_JSON_SCHEMA

    p = _raw_file(tmp_path / "j.mcap", ("foxglove.RawImage", "jsonschema", RAW_JSON_SCHEMA), "json",
                  [json.dumps({"width": 2, "height": 2, "encoding": "32FC1", "step": 8}).encode()])
    _, err = read_until_error(p, topic="/cam/depth")
    assert "not a foxglove RawImage JSON message" in one_line(err) and "data" in str(err)


def test_file_without_depth_images(tmp_path):
    p = _raw_file(tmp_path / "n.mcap", ("depthseg/Scene", "jsonschema", b"{}"), "json", [b"{}"] * 3, topic="/scene")
    with pytest.raises(McapDataError) as e:
        open_depth_stream(p)
    msg = one_line(e.value)
    assert "no depth images" in msg and "/scene (depthseg/Scene)" in msg
    labels_only = tmp_path / "l.mcap"
    _raw_file(labels_only, (rosmsg.IMAGE_TYPE, "ros2msg", rosmsg.IMAGE_MSGDEF.encode()), "cdr",
              [rosmsg.encode_image(1, "c", np.zeros((4, 4), np.uint8), "mono8")], topic="/labels")
    with pytest.raises(McapDataError, match=r"no depth image topic.*/labels \(sensor_msgs/msg/Image, mono8, 4x4\)"):
        open_depth_stream(labels_only)


def test_recording_without_messages(tmp_path):
    p = _raw_file(tmp_path / "e.mcap", (rosmsg.IMAGE_TYPE, "ros2msg", rosmsg.IMAGE_MSGDEF.encode()), "cdr", [])
    with pytest.raises(McapDataError, match=r"/cam/depth \(sensor_msgs/msg/Image, no messages\)"):
        open_depth_stream(p)


@pytest.mark.parametrize(
    "make, expect",
    [
        (lambda p: p.write_bytes(b""), "empty file (0 bytes)"),
        (lambda p: p.mkdir(), "is a directory"),
        (lambda p: None, "no such file"),
        (lambda p: p.write_text("hello, not a bag\n"), "not an MCAP file"),
        (lambda p: p.write_bytes(b"\x89MCA"), "truncated inside the MCAP magic"),
        (lambda p: p.write_bytes(b"\x89MCAP0\r\n\x01\x05"), "damage"),
    ],
    ids=["empty", "directory", "missing", "text", "short-magic", "cut-after-magic"],
)
def test_not_a_recording(tmp_path, make, expect):
    p = tmp_path / "x.mcap"
    make(p)
    with pytest.raises(McapDataError) as e:
        open_depth_stream(p)
    assert expect in one_line(e.value)


def test_file_cut_before_the_first_frame_reports_the_damage(tmp_path):
    rec = write_ros2(tmp_path / "a.mcap", n=4)
    cut = tmp_path / "c.mcap"
    cut.write_bytes(rec.path.read_bytes()[:200])
    with pytest.raises(McapDataError) as e:
        open_depth_stream(cut)
    msg = one_line(e.value)
    assert "damage" in msg and "truncated" in msg


# ------------------------------------------------------------------ the shared foreign files

MCAP_DIR = SHARED / "data" / "mcap"
needs_shared = pytest.mark.skipif(not MCAP_DIR.is_dir(), reason=f"{MCAP_DIR} not present (../shared beside the repo)")


@needs_shared
def test_rosbag2_wrong_rmw():
    p = MCAP_DIR / "rosbag2_wrong_rmw.mcap"
    with pytest.raises(McapDataError) as e:
        open_depth_stream(p)
    msg = one_line(e.value)
    assert "message encoding 'wrong_format' cannot be decoded" in msg and "/test_topic" in msg
    with pytest.raises(McapDataError, match="/test_topic carries 'test_msgs/msg/BasicTypes'"):
        open_depth_stream(p, topic="/test_topic")


@needs_shared
def test_rosbags_test_bag_malformed_image():
    p = MCAP_DIR / "rosbags_test_bag.mcap"
    with pytest.raises(McapDataError) as e:
        open_depth_stream(p)
    msg = one_line(e.value)
    assert "no depth image topic" in msg and "/test/sensor_msgs/image (sensor_msgs/msg/Image, rgb8, 640x480)" in msg
    frames, err = read_until_error(p, topic="/test/sensor_msgs/image")
    assert frames == []
    msg = one_line(err)
    assert "data has 30 bytes but height x step = 480 x 1920" in msg and "malformed" in msg


def test_flipped_pixel_bytes_in_an_uncompressed_chunk_fail_the_crc(tmp_path):
    """Without compression a flipped pixel still parses; only the chunk CRC can tell."""
    from mcap.writer import CompressionType

    rec = write_ros2(tmp_path / "raw.mcap", n=N, compression=CompressionType.NONE)
    data = bytearray(rec.path.read_bytes())
    start, length = chunk_spans(rec.path)[N // 2]
    data[start + length - 100] ^= 0x01  # a pixel byte near the end of the chunk
    bad = tmp_path / "flip.mcap"
    bad.write_bytes(bytes(data))
    frames, err = read_until_error(bad)
    assert err is not None and "checksum mismatch" in one_line(err)
    assert 0 < len(frames) < N
    assert_prefix_intact(frames, rec)

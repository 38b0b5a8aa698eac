"""The streaming reader on intact recordings: every supported layout, topic choice, pairing."""

from __future__ import annotations

import numpy as np
import pytest
from mcap.writer import Writer
from replaygen import KINDS, T0, scene, write_foxglove, write_kind, write_ros2

from edge import rosmsg
from edge.errors import McapDataError
from edge.io import FrameWriter
from edge.io.reader import open_depth_stream


def same_depth(a: np.ndarray, b: np.ndarray) -> bool:
    return a.shape == b.shape and bool(np.array_equal(a, b, equal_nan=True))


@pytest.mark.parametrize("kind", KINDS)
def test_every_layout_roundtrips(kind, tmp_path):
    rec = write_kind(kind, tmp_path / f"{kind}.mcap", n=7)
    s = open_depth_stream(rec.path)
    assert s.depth_topic == rec.topic
    assert s.labels_topic == rec.labels_topic
    assert s.frame_count == 7
    frames = list(s)
    assert len(frames) == 7 == s.frames_read
    assert s.damage is None
    for i, fr in enumerate(frames):
        assert fr.depth.dtype == np.float32
        assert same_depth(fr.depth, rec.depth[i]), f"frame {i} differs"
        assert np.array_equal(fr.label, rec.label[i])
        assert fr.stamp_ns == T0 + i * 50_000_000
        assert fr.extra["header_stamp_ns"] == fr.stamp_ns
        assert fr.extra["frame_id"] == "cam"


def test_invalid_markers_are_kept_for_the_preprocessing(tmp_path):
    """0 stays 0 and NaN stays NaN: edge.preprocess decides validity, and both are invalid there."""
    from edge.preprocess import valid_mask

    zero = list(open_depth_stream(write_kind("ros32_zero", tmp_path / "z.mcap", n=2).path))
    nan = list(open_depth_stream(write_kind("ros32_nan", tmp_path / "n.mcap", n=2).path))
    mm = list(open_depth_stream(write_kind("ros16", tmp_path / "m.mcap", n=2).path))
    assert (zero[0].depth == 0).sum() > 4 and not np.isnan(zero[0].depth).any()
    assert np.isnan(nan[0].depth).sum() == (zero[0].depth == 0).sum()
    for a, b, c in zip(zero, nan, mm):
        assert np.array_equal(valid_mask(a.depth), valid_mask(b.depth))
        assert np.array_equal(valid_mask(a.depth), valid_mask(c.depth))
        assert np.allclose(c.depth, np.nan_to_num(a.depth), atol=6e-4)  # millimetre rounding


def test_camera_info_is_used(tmp_path):
    rec = write_ros2(tmp_path / "a.mcap", n=2)
    s = open_depth_stream(rec.path)
    assert s.info_topic == "/pico_flexx/camera_info"
    assert s.camera_info["fx"] == 200.0 and s.camera_info["fy"] == 201.0
    fr = next(iter(s))
    assert fr.info["width"] == 32 and fr.info["height"] == 24


def test_sim_layout_with_clean_depth_and_noise_topics(tmp_path):
    """Our own files carry a second 32FC1 topic (clean depth): it must not count as a candidate."""
    p = tmp_path / "sim.mcap"
    with FrameWriter(p) as w:
        for i in range(3):
            d, lab = scene(i)
            w.write_image("/pico_flexx/image_noise", T0 + i, np.full_like(d, 0.003), "32FC1")
            w.write(T0 + i, d, label=lab, intrinsics=(1, 1, 1, 1), clean=d, scene={"i": i})
    s = open_depth_stream(p)
    assert (s.depth_topic, s.labels_topic) == ("/pico_flexx/image_depth", "/pico_flexx/labels")
    assert [fr.label is not None for fr in s] == [True] * 3


def test_several_depth_topics_are_listed_and_topic_chooses(tmp_path):
    d, _ = scene(0)
    rec = write_ros2(tmp_path / "two.mcap", n=3, topic="/cam_a/points_z",
                     extra={"/cam_b/range_image": ("32FC1", d)})
    with pytest.raises(McapDataError) as e:
        open_depth_stream(rec.path)
    msg = str(e.value)
    assert "several depth image topics" in msg and "/cam_a/points_z" in msg and "/cam_b/range_image" in msg
    assert "`depth_topic`" in msg and "\n" not in msg
    s = open_depth_stream(rec.path, topic="/cam_b/range_image")
    assert s.depth_reason == "chosen explicitly" and len(list(s)) == 3


def test_depth_name_breaks_a_tie(tmp_path):
    d, _ = scene(0)
    rec = write_ros2(tmp_path / "tie.mcap", n=2, topic="/flexx/depth_image_0", extra={"/flexx/xyz_z": ("32FC1", d)})
    assert open_depth_stream(rec.path).depth_topic == "/flexx/depth_image_0"


def test_mono16_grey_image_is_not_depth_but_16uc1_is(tmp_path):
    d, _ = scene(0)
    rec = write_ros2(tmp_path / "g.mcap", n=2, extra={"/pico_flexx/image_mono16": ("mono16", (d * 1000).astype(np.uint16))})
    assert open_depth_stream(rec.path).depth_topic == "/pico_flexx/image_depth"


def test_missing_topic_lists_image_topics(tmp_path):
    rec = write_ros2(tmp_path / "a.mcap", n=2)
    with pytest.raises(McapDataError, match=r"no depth topic '/nope'.*/pico_flexx/image_depth.*`depth_topic`"):
        open_depth_stream(rec.path, topic="/nope")
    with pytest.raises(McapDataError, match=r"no labels topic '/nope'"):
        open_depth_stream(rec.path, labels_topic="/nope")
    with pytest.raises(McapDataError, match="not sensor_msgs/msg/Image"):
        open_depth_stream(rec.path, topic="/pico_flexx/camera_info")


def test_labels_can_be_disabled(tmp_path):
    rec = write_ros2(tmp_path / "a.mcap", n=3)
    s = open_depth_stream(rec.path, labels_topic="")
    assert s.labels_topic is None
    assert all(fr.label is None for fr in s)


def test_without_labels_frames_have_none(tmp_path):
    rec = write_foxglove(tmp_path / "a.mcap", n=3, labels=False)
    s = open_depth_stream(rec.path)
    assert s.labels_topic is None and [fr.label for fr in s] == [None] * 3


def _write_pairs(path, events):
    """events: (kind, log_time, header_stamp, index) written in the given file order."""
    with open(path, "wb") as fh:
        w = Writer(fh, chunk_size=2048)
        w.start(profile="ros2", library="test")
        sid = w.register_schema(rosmsg.IMAGE_TYPE, "ros2msg", rosmsg.IMAGE_MSGDEF.encode())
        ch = {"d": w.register_channel("/cam/depth", "cdr", sid), "l": w.register_channel("/cam/labels", "cdr", sid)}
        for kind, log_t, stamp, i in events:
            d, lab = scene(i)
            arr, enc = (d, "32FC1") if kind == "d" else (lab * 0 + np.uint8(i + 1), "mono8")
            w.add_message(ch[kind], log_t, rosmsg.encode_image(stamp, "cam", arr, enc), log_t)
        w.finish()


def test_labels_pair_by_header_stamp_in_any_order_and_may_be_missing(tmp_path):
    p = tmp_path / "pairs.mcap"
    ms = 1_000_000
    events = [
        ("l", 5, 1000 * ms, 0), ("d", 10, 1000 * ms, 0),  # label before depth
        ("d", 20, 1050 * ms, 1), ("l", 30, 1050 * ms + ms // 2, 1),  # label after, 0.5 ms jitter
        ("d", 40, 1100 * ms, 2),  # no label at all
        ("d", 50, 1150 * ms, 3), ("l", 60, 1150 * ms, 3),
        ("d", 70, 1200 * ms, 4),  # the last one, unlabelled
    ]
    _write_pairs(p, events)
    frames = list(open_depth_stream(p))
    assert [f.extra["index"] for f in frames] == [0, 1, 2, 3, 4]
    got = [None if f.label is None else int(f.label.max()) for f in frames]
    assert got == [1, 1, None, 1, None]  # labels are binarised: nonzero = object
    assert [f.stamp_ns for f in frames] == [10, 20, 40, 50, 70]  # log time is the frame time


def test_unpaired_labels_do_not_pile_up(tmp_path):
    """Labels that never meet their depth frame are dropped after the window."""
    p = tmp_path / "stray.mcap"
    events = [("l", i, 10_000_000_000 + i * 1_000_000_000, 0) for i in range(50)] + [("d", 100, 5, 0)]
    _write_pairs(p, events)
    s = open_depth_stream(p, labels_topic="/cam/labels", window=8)
    frames = list(s)
    assert len(frames) == 1 and frames[0].label is None


def test_registered_but_empty_label_topic_is_not_used(tmp_path):
    """FrameWriter registers /pico_flexx/labels even for unlabelled captures (e.g. imported PLY)."""
    p = tmp_path / "nolabels.mcap"
    with FrameWriter(p) as w:
        for i in range(2):
            w.write(T0 + i, scene(i)[0], intrinsics=(1, 1, 1, 1))
    s = open_depth_stream(p)
    assert s.labels_topic is None and s.topics["/pico_flexx/labels"].n_messages == 0
    assert [fr.label for fr in s] == [None, None]


def test_data_section_crc_and_uncompressed_chunks_read_cleanly(tmp_path):
    """CRCs are verified, so a writer that adds the optional data-section CRC must still pass."""
    from mcap.writer import CompressionType

    p = tmp_path / "crc.mcap"
    with open(p, "wb") as fh:
        w = Writer(fh, chunk_size=4096, enable_data_crcs=True, compression=CompressionType.NONE)
        w.start("ros2", "test")
        sid = w.register_schema(rosmsg.IMAGE_TYPE, "ros2msg", rosmsg.IMAGE_MSGDEF.encode())
        ch = w.register_channel("/d", "cdr", sid)
        for i in range(5):
            w.add_message(ch, i + 1, rosmsg.encode_image(i + 1, "c", scene(i)[0], "32FC1"), i + 1)
        w.finish()
    s = open_depth_stream(p)
    assert len(list(s)) == 5 and s.damage is None


def test_foxglove_camera_calibration_json_is_used(tmp_path):
    import json

    from replaygen import write_foxglove

    rec = write_foxglove(tmp_path / "f.mcap", n=2, fmt="json")
    # append a foxglove.CameraCalibration channel to a copy of the recording
    p = tmp_path / "cal.mcap"
    with open(p, "wb") as fh:
        w = Writer(fh)
        w.start("", "test")
        raw = w.register_schema("foxglove.RawImage", "jsonschema", b"{}")
        cal = w.register_schema("foxglove.CameraCalibration", "jsonschema", b"{}")
        ch_d = w.register_channel("/camera/depth", "json", raw)
        ch_c = w.register_channel("/camera/calibration", "json", cal)
        k = [210.0, 0, 16.0, 0, 212.0, 12.0, 0, 0, 1]
        w.add_message(ch_c, 1, json.dumps({"width": 32, "height": 24, "K": k, "D": [0.1], "frame_id": "cam"}).encode(), 1)
        from mcap.reader import make_reader

        with open(rec.path, "rb") as src:
            for _, _, m in make_reader(src).iter_messages(topics=["/camera/depth"]):
                w.add_message(ch_d, m.log_time, m.data, m.publish_time)
        w.finish()
    s = open_depth_stream(p)
    assert s.info_topic == "/camera/calibration"
    assert (s.camera_info["fx"], s.camera_info["fy"], s.camera_info["cx"]) == (210.0, 212.0, 16.0)
    assert [fr.info["d"] for fr in s] == [[0.1, 0.0, 0.0, 0.0]] * 2  # padded to a length OpenCV takes

"""The replay loop and its output recording (stand-in segmenter and a real ONNX model)."""

from __future__ import annotations

import math
import time

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory as Ros2DecoderFactory
from replaygen import FakeSegmenter, scene, write_foxglove, write_kind, write_ros2

from edge.errors import ConfigError
from edge.io import Frame
from edge.io.reader import open_depth_stream
from edge.metrics import logit, segmentation_mask
from edge.preprocess import valid_mask
from replay.replay import LatencyHistogram, ReplayDataError, replay
from replay.writer import MASK_COLOURS, MASK_RAW_TOPIC, MASK_TOPIC, OVERLAY_TOPIC, UNKNOWN_RGB, overlay_rgb


def mem_frames(n=4, size=(24, 32), labels=True) -> list[Frame]:
    out = []
    for i in range(n):
        d, lab = scene(i, *size)
        out.append(Frame(depth=d, stamp_ns=i * 50_000_000, label=lab if labels else None))
    return out


def test_perfect_inverted_and_unlabelled(fake, tmp_path):
    rec = write_kind("ros32_nan", tmp_path / "a.mcap", n=5)
    s = replay(open_depth_stream(rec.path), fake)
    assert s.frames == 5 and s.labelled_frames == 5 and s.error is None
    m = s.metrics
    assert (m.iou, m.precision, m.recall, m.pixel_accuracy) == (1.0, 1.0, 1.0, 1.0)
    inv = replay(open_depth_stream(rec.path), FakeSegmenter(invert=True))
    assert inv.metrics.iou == 0.0 and inv.metrics.recall == 0.0
    d = replay(open_depth_stream(rec.path, labels_topic=""), fake).to_dict()
    assert {"frames", "fps", "p50_ms", "p90_ms", "p99_ms"} <= set(d)
    assert not {"iou", "precision", "recall", "pixel_accuracy"} & set(d)
    assert d["frames"] == 5 and d["fps"] > 0


def test_unknown_pixels_are_reported_and_never_scored(fake):
    frames = mem_frames(3)
    invalid = [~valid_mask(f.depth) for f in frames]
    for f, inv in zip(frames, invalid):
        f.label = f.label.copy()
        f.label[inv] = 1  # labels on dead pixels must not matter
    masks = []
    s = replay(frames, fake, on_frame=lambda r: masks.append(r.mask.copy()))
    assert s.metrics.iou == 1.0
    for m, inv in zip(masks, invalid):
        assert np.array_equal(m == 255, inv)
        assert set(np.unique(m)) <= {0, 1, 255}
    expect = sum(int(i.sum()) for i in invalid) / sum(i.size for i in invalid)
    assert s.unknown_fraction == pytest.approx(expect)


def test_threshold_override_recomputes_the_mask(fake):
    frames = mem_frames(2)
    got = {}
    for t in (0.2, 0.5, 0.9):
        got[t] = []
        s = replay(frames, fake, threshold=t, on_frame=lambda r, t=t: got[t].append(r.mask.copy()))
        assert s.threshold == t
    for f, m in zip(frames, got[0.9]):
        p = fake.predict(f.depth)
        assert np.array_equal(m, segmentation_mask(logit(p.prob.astype(np.float32)), p.valid, 0.9))
    for bad in (0.0, 1.0, 1.5):
        with pytest.raises(ConfigError, match="threshold"):
            replay(frames, fake, threshold=bad)


def test_rate_paces_to_the_recording_clock(fake):
    frames = mem_frames(5)  # 50 ms apart: 200 ms of recording
    t = time.perf_counter()
    s = replay(frames, fake, rate=1.0)
    assert time.perf_counter() - t >= 0.19
    assert s.rate == 1.0 and s.to_dict()["late_frames"] == s.late_frames
    t = time.perf_counter()
    replay(frames, fake, rate=4.0)
    assert time.perf_counter() - t >= 0.045
    for bad in (0.0, -1.0, math.nan, math.inf):
        with pytest.raises(ConfigError, match="`rate`"):
            replay(frames, fake, rate=bad)


def test_slow_model_frames_are_counted_late():
    class Slow(FakeSegmenter):
        def predict(self, depth):
            time.sleep(0.03)
            return super().predict(depth)

    frames = [Frame(depth=f.depth, stamp_ns=i * 10_000_000) for i, f in enumerate(mem_frames(5))]  # 100 fps
    s = replay(frames, Slow(), rate=1.0)
    assert s.late_frames >= 3


def test_other_frame_sizes_through_a_real_onnx_model(linear_onnx):
    from edge.infer import Segmenter

    seg = Segmenter(linear_onnx, threads=1)
    frames = []
    rng = np.random.default_rng(5)
    for i, (h, w) in enumerate([(24, 32), (171, 224), (50, 70), (33, 31), (240, 320)]):
        d = (0.30 + rng.normal(0, 0.002, (h, w))).astype(np.float32)
        lab = np.zeros((h, w), np.uint8)
        lab[h // 4 : h // 2 + 1, w // 3 : 2 * w // 3 + 1] = 1  # a box covering ~1/6 of any frame
        d[lab == 1] -= 0.05
        d[0, :3] = 0.0
        frames.append(Frame(depth=d, stamp_ns=i, label=lab))
    shapes = []
    s = replay(frames, seg, on_frame=lambda r: shapes.append(r.mask.shape))
    assert shapes == [f.depth.shape for f in frames]
    assert s.sizes == shapes
    assert s.metrics.iou > 0.9  # nearer-than-average is object: right on these scenes
    assert s.latency.n == 5 and s.to_dict()["p50_ms"] > 0


def test_latency_histogram_percentiles():
    rng = np.random.default_rng(3)
    x = rng.lognormal(mean=1.0, sigma=0.6, size=5000)
    h = LatencyHistogram()
    for v in x:
        h.add(v)
    for q in (50, 90, 99):
        exact = float(np.percentile(x, q, method="inverted_cdf"))
        assert h.percentile(q) == pytest.approx(exact, rel=0.005)
    assert h.percentile(100) == pytest.approx(x.max())
    assert math.isnan(LatencyHistogram().percentile(50))
    assert h.counts.nbytes < 64 * 1024  # constant memory, whatever the number of frames


# ------------------------------------------------------------------ output recording


def read_out(path):
    """topic -> list of (log_time, decoded ROS message or raw bytes), via mcap's own reader."""
    out = {}
    with open(path, "rb") as fh:
        r = make_reader(fh, decoder_factories=[Ros2DecoderFactory()])
        summary = r.get_summary()
        assert summary is not None and summary.statistics.message_count > 0  # complete, indexed file
        for schema, ch, msg in r.iter_messages():
            out.setdefault(ch.topic, []).append((msg.log_time, schema, msg))
    return out


def test_output_copies_everything_and_adds_mask_and_overlay(fake, tmp_path):
    rec = write_ros2(tmp_path / "in.mcap", n=4, invalid="nan")
    out = tmp_path / "out.mcap"
    s = replay(open_depth_stream(rec.path), fake, out=out)
    assert s.out == str(out) and out.exists()
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []  # temp renamed away
    src, dst = read_out(rec.path), read_out(out)
    for topic, msgs in src.items():
        assert [(t, m.data) for t, _, m in dst[topic]] == [(t, m.data) for t, _, m in msgs], topic
    depth_times = [t for t, _, _ in src[rec.topic]]
    dec = Ros2DecoderFactory()
    for topic in (MASK_TOPIC, MASK_RAW_TOPIC, OVERLAY_TOPIC):
        assert [t for t, _, _ in dst[topic]] == depth_times
    for i, (t, schema, msg) in enumerate(dst[MASK_RAW_TOPIC]):
        m = dec.decoder_for("cdr", schema)(msg.data)  # an independent CDR decoder reads it
        assert (m.encoding, m.height, m.width) == ("mono8", 24, 32)
        assert m.header.stamp.sec * 10**9 + m.header.stamp.nanosec == t and m.header.frame_id == "cam"
        mask = np.frombuffer(bytes(m.data), np.uint8).reshape(24, 32)
        assert np.array_equal(mask == 255, np.isnan(rec.depth[i]))
        assert np.array_equal(mask[mask != 255], rec.label[i][mask != 255])
        # the displayable mask: the same classes as colours (table, object, unknown visibly apart)
        c = dec.decoder_for("cdr", dst[MASK_TOPIC][i][1])(dst[MASK_TOPIC][i][2].data)
        assert (c.encoding, c.step) == ("rgb8", 32 * 3)
        assert np.array_equal(np.frombuffer(bytes(c.data), np.uint8).reshape(24, 32, 3), MASK_COLOURS[mask])
    ov = dec.decoder_for("cdr", dst[OVERLAY_TOPIC][0][1])(dst[OVERLAY_TOPIC][0][2].data)
    assert ov.encoding == "rgb8" and ov.step == 32 * 3
    rgb = np.frombuffer(bytes(ov.data), np.uint8).reshape(24, 32, 3)
    assert np.all(rgb[np.isnan(rec.depth[0])] == UNKNOWN_RGB)
    # replaying the output again works: the mask topics are not mistaken for depth
    again = open_depth_stream(out)
    assert again.depth_topic == rec.topic and again.labels_topic == rec.labels_topic


def test_foxglove_input_output_keeps_protobuf_schemas(fake, tmp_path):
    rec = write_foxglove(tmp_path / "in.mcap", n=3, fmt="protobuf")
    out = tmp_path / "out.mcap"
    replay(open_depth_stream(rec.path), fake, out=out)
    dst = read_out(out)
    assert dst[rec.topic][0][1].encoding == "protobuf" and len(dst[MASK_TOPIC]) == 3
    assert open_depth_stream(out).depth_topic == rec.topic  # our copy decodes like the original


def test_damaged_input_still_gives_a_valid_output(fake, tmp_path):
    rec = write_kind("fox_json", tmp_path / "in.mcap", n=8)
    data = rec.path.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: len(data) * 6 // 10])
    out = tmp_path / "out.mcap"
    with pytest.raises(ReplayDataError) as e:
        replay(open_depth_stream(cut), fake, out=out)
    s = e.value.summary
    assert 0 < s.frames < 8 and s.error == str(e.value) and "damaged at byte" in s.error
    assert s.metrics.iou == 1.0
    dst = read_out(out)
    assert len(dst[MASK_TOPIC]) == s.frames
    assert len(dst[rec.topic]) >= s.frames
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []


def test_model_failure_leaves_no_output(tmp_path):
    class Broken(FakeSegmenter):
        def predict(self, depth):
            if self.calls >= 2:
                raise RuntimeError("boom")
            return super().predict(depth)

    rec = write_ros2(tmp_path / "in.mcap", n=4)
    out = tmp_path / "out.mcap"
    with pytest.raises(RuntimeError):
        replay(open_depth_stream(rec.path), Broken(), out=out)
    assert not out.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["in.mcap"]


def test_overlay_colours():
    d, _ = scene(0)
    mask = np.zeros(d.shape, np.uint8)
    mask[5:8, 5:8] = 1
    mask[d == 0] = 255
    rgb = overlay_rgb(d, mask)
    assert rgb.dtype == np.uint8 and rgb.shape == d.shape + (3,)
    bg = rgb[(mask == 0)]
    assert np.all(bg[:, 0] == bg[:, 1]) and np.all(bg[:, 1] == bg[:, 2])  # grey
    obj = rgb[mask == 1].astype(int)
    assert np.all(obj[:, 0] > obj[:, 2] + 60)  # orange: red well above blue
    assert np.all(rgb[mask == 255] == UNKNOWN_RGB)

"""Memory stays flat on long recordings: 10,000 frames streamed, RSS growth bounded.

Small frames (24 x 32) keep it fast; what is measured is whether anything accumulates per frame
(a list of frames or labels, a latency list, unbounded pairing buffers). Frames of 3 kB plus
labels: keeping them all would add ~40 MB, far above the bound used here.
"""

from __future__ import annotations

import gc

import numpy as np
import psutil
import pytest
from mcap.writer import CompressionType, Writer
from replaygen import FakeSegmenter

from edge import rosmsg
from edge.io import Frame
from edge.io.reader import open_depth_stream
from replay.replay import replay

N = 10_000
H, W = 24, 32
BOUND_MB = 12.0


def write_long(path) -> None:
    rng = np.random.default_rng(11)
    base = (0.3 + rng.normal(0, 0.002, (H, W))).astype(np.float32)
    lab = np.zeros((H, W), np.uint8)
    lab[5:12, 8:20] = 1
    with open(path, "wb") as fh:
        w = Writer(fh, chunk_size=256 * 1024, compression=CompressionType.ZSTD)
        w.start(profile="ros2", library="test")
        sid = w.register_schema(rosmsg.IMAGE_TYPE, "ros2msg", rosmsg.IMAGE_MSGDEF.encode())
        cd = w.register_channel("/pico_flexx/image_depth", "cdr", sid)
        cl = w.register_channel("/pico_flexx/labels", "cdr", sid)
        lab_msg_cache = {}
        for i in range(N):
            t = 1_000_000_000 + i * 22_000_000
            d = base.copy()
            d[i % H, :] = 0.0  # a moving dead row
            w.add_message(cd, t, rosmsg.encode_image(t, "cam", d, "32FC1"), t)
            lab_msg_cache[t] = rosmsg.encode_image(t, "cam", lab, "mono8")
            w.add_message(cl, t, lab_msg_cache.pop(t), t)
        w.finish()


def rss_mb() -> float:
    gc.collect()
    return psutil.Process().memory_info().rss / 2**20


@pytest.mark.slow
def test_memory_is_flat_over_10000_frames(tmp_path):
    src = tmp_path / "long.mcap"
    write_long(src)
    stream = open_depth_stream(src)
    assert stream.frame_count == N and stream.labels_topic == "/pico_flexx/labels"
    samples: dict[int, float] = {}

    def on_frame(r) -> None:
        if r.index in (1_000, N - 1):
            samples[r.index] = rss_mb()

    s = replay(stream, FakeSegmenter(cut=0.29), out=tmp_path / "out.mcap", on_frame=on_frame)
    assert s.frames == N and s.labelled_frames == N
    growth = samples[N - 1] - samples[1_000]
    assert growth < BOUND_MB, f"RSS grew {growth:.1f} MB over {N - 1_000} frames (replay + writer)"

    # the reader alone, frames dropped as they come
    before = None
    for i, fr in enumerate(open_depth_stream(src)):
        assert isinstance(fr, Frame)
        if i == 1_000:
            before = rss_mb()
    assert rss_mb() - before < BOUND_MB

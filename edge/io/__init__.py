"""MCAP in and out: the one reader, the one writer base, the one atomic writer.

- `edge.io.frames`: the depthseg layout (topic names) and `Frame`.
- `edge.io.reader`: `open_depth_stream` (one recording) and `open_frames` / `iter_frames` (a
  file or a directory): damage tolerant, streaming in file order, topics detected, labels and
  the simulator's extras paired with depth by timestamp.
- `edge.io.bags`: ROS 1 .bag, ROS 2 .db3 and bag directories (``rosbags``, the ``ros`` extra) as
  the reader's MCAP records; `edge.io.compressed`: compressedDepth (16-bit PNG) decoding.
- `edge.io.writer`: `McapWriter` (atomic, compressed) and `FrameWriter` (the depthseg layout).
- `edge.io.atomic`: `atomic_write` and friends, for every other output file; `edge.io.paths`: which
  paths may be read and written; `edge.io.chunks`: bounded decompression of MCAP and bag chunks.
"""

from edge.io.atomic import atomic_path, atomic_write, write_bytes_atomic, write_json_atomic
from edge.io.frames import (
    FRAME_ID,
    SIM_EPOCH_NS,
    TOPIC_CLEAN,
    TOPIC_DEPTH,
    TOPIC_INFO,
    TOPIC_LABELS,
    TOPIC_SCENE,
    Frame,
    decode_scene,
)
from edge.io.reader import DepthStream, iter_frames, list_mcap_files, open_depth_stream, open_frames
from edge.io.writer import FrameWriter, McapWriter

__all__ = [
    "FRAME_ID", "SIM_EPOCH_NS", "TOPIC_CLEAN", "TOPIC_DEPTH", "TOPIC_INFO", "TOPIC_LABELS", "TOPIC_SCENE", "Frame",
    "decode_scene",
    "DepthStream", "open_depth_stream", "open_frames", "iter_frames", "list_mcap_files",
    "FrameWriter", "McapWriter", "atomic_path", "atomic_write", "write_bytes_atomic", "write_json_atomic",
]

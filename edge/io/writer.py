"""The MCAP writers: one base (compression, temporary file, atomic close, abort) and the depthseg layout.

Why one base: a recording must appear under its final name only when it is complete and
indexed (a resumed simulation trusts every ``frames_*.mcap`` it finds; a replay output that
exists can be opened in Foxglove). `McapWriter` owns that: it writes to `edge.io.atomic.atomic_path`,
`close` finishes the index and footer, fsyncs and renames, `abort` (or an exception inside a
``with`` block) removes the temporary file. `FrameWriter` writes the layout of `edge.io.frames`
(``depthseg-sim`` and the importers); `replay.writer.ReplayWriter` copies a recording and adds
mask and overlay topics.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any, BinaryIO

import numpy as np
from mcap.writer import CompressionType, Writer

from edge import rosmsg
from edge.errors import DataError
from edge.io.atomic import atomic_path
from edge.io.frames import FRAME_ID, TOPIC_CLEAN, TOPIC_DEPTH, TOPIC_INFO, TOPIC_LABELS, TOPIC_SCENE

__all__ = ["McapWriter", "FrameWriter", "COMPRESSIONS"]

COMPRESSIONS = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4, "none": CompressionType.NONE}


class McapWriter:
    """An MCAP file written to a temporary sibling and renamed into place by `close`.

    Args:
        path: the final file name; its directory must exist.
        profile: the MCAP header profile (``"ros2"`` or ``""``).
        library: the MCAP header library string.
        compression: ``zstd``, ``lz4`` or ``none``.
        chunk_size: bytes per chunk before compression.

    Raises:
        DataError: ``path`` is a directory, its directory is missing, or the compression is unknown.
    """

    def __init__(
        self,
        path: str | Path,
        profile: str = "ros2",
        library: str = "depthseg",
        compression: str = "zstd",
        chunk_size: int = 4 * 1024 * 1024,
    ) -> None:
        self.path = Path(path)
        if self.path.is_dir():
            raise DataError(f"{self.path}: is a directory; the output needs a file name such as out.mcap")
        if not self.path.parent.exists():
            raise DataError(f"{self.path.parent}: output directory does not exist")
        if compression not in COMPRESSIONS:
            raise DataError(f"unknown compression '{compression}'; choose from {sorted(COMPRESSIONS)}")
        self.tmp = atomic_path(self.path)
        self._fh: BinaryIO = open(self.tmp, "wb")
        self._w = Writer(self._fh, chunk_size=chunk_size, compression=COMPRESSIONS[compression])
        self._w.start(profile=profile, library=library)
        self._image_schema = self._w.register_schema(rosmsg.IMAGE_TYPE, "ros2msg", rosmsg.IMAGE_MSGDEF.encode())
        self._closed = False

    def image_channel(self, topic: str) -> int:
        """Register a ``sensor_msgs/msg/Image`` (CDR) channel on ``topic``; returns its id."""
        return self._w.register_channel(topic, "cdr", self._image_schema)

    def add_image(self, channel: int, log_ns: int, stamp_ns: int, frame_id: str, array: np.ndarray,
                  encoding: str, sequence: int = 0) -> None:
        """One Image message: log and publish time ``log_ns``, header stamp ``stamp_ns``."""
        data = rosmsg.encode_image(int(stamp_ns), frame_id, np.asarray(array), encoding)
        self._w.add_message(channel, log_time=int(log_ns), publish_time=int(log_ns), data=data, sequence=sequence)

    def close(self) -> None:
        """Finish the index and footer, fsync, then rename into place (once; later calls do nothing)."""
        if self._closed:
            return
        self._closed = True
        try:
            self._w.finish()
            self._fh.flush()
            os.fsync(self._fh.fileno())
            self._fh.close()
            os.replace(self.tmp, self.path)
        except BaseException:
            self._fh.close()
            self.tmp.unlink(missing_ok=True)
            raise

    def abort(self) -> None:
        """Drop the partial output: nothing appears under the final name."""
        if self._closed:
            return
        self._closed = True
        try:
            self._fh.close()
        finally:
            self.tmp.unlink(missing_ok=True)

    def __enter__(self):
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is None:
            self.close()
        else:
            self.abort()


class FrameWriter(McapWriter):
    """Write frames in the depthseg layout (`edge.io.frames`); the file appears only when complete.

    Use as a context manager. On an exception the temporary file is removed, so a reader never
    sees a partial file under the final name (a resumed run regenerates it).
    """

    def __init__(self, path: str | Path, compression: str = "zstd", chunk_size: int = 4 * 1024 * 1024) -> None:
        super().__init__(path, profile="ros2", library="depthseg", compression=compression, chunk_size=chunk_size)
        info = self._w.register_schema(rosmsg.CAMERA_INFO_TYPE, "ros2msg", rosmsg.CAMERA_INFO_MSGDEF.encode())
        scene = self._w.register_schema(rosmsg.STRING_TYPE, "ros2msg", rosmsg.STRING_MSGDEF.encode())
        self._ch = {
            TOPIC_DEPTH: self.image_channel(TOPIC_DEPTH),
            TOPIC_LABELS: self.image_channel(TOPIC_LABELS),
            TOPIC_INFO: self._w.register_channel(TOPIC_INFO, "cdr", info),
            TOPIC_CLEAN: self.image_channel(TOPIC_CLEAN),
            TOPIC_SCENE: self._w.register_channel(TOPIC_SCENE, "cdr", scene, {"content": "application/json"}),
        }
        self.count = 0

    def write(
        self,
        stamp_ns: int,
        depth: np.ndarray,
        label: np.ndarray | None = None,
        intrinsics: tuple[float, float, float, float] | None = None,
        clean: np.ndarray | None = None,
        scene: dict[str, Any] | None = None,
        distortion: tuple[float, ...] = (),
    ) -> None:
        """One frame: every message with log time and header stamp ``stamp_ns``."""
        t = int(stamp_ns)
        seq = self.count
        depth = np.asarray(depth, dtype=np.float32)
        if intrinsics is not None:
            fx, fy, cx, cy = intrinsics
            h, w = depth.shape
            data = rosmsg.encode_camera_info(t, FRAME_ID, w, h, fx, fy, cx, cy, distortion)
            self._w.add_message(self._ch[TOPIC_INFO], log_time=t, publish_time=t, data=data, sequence=seq)
        self.add_image(self._ch[TOPIC_DEPTH], t, t, FRAME_ID, depth, "32FC1", seq)
        if label is not None:
            self.add_image(self._ch[TOPIC_LABELS], t, t, FRAME_ID, np.asarray(label, dtype=np.uint8), "mono8", seq)
        if clean is not None:
            self.add_image(self._ch[TOPIC_CLEAN], t, t, FRAME_ID, np.asarray(clean, dtype=np.float32), "32FC1", seq)
        if scene is not None:
            data = rosmsg.encode_string(json.dumps(scene, sort_keys=True))
            self._w.add_message(self._ch[TOPIC_SCENE], log_time=t, publish_time=t, data=data, sequence=seq)
        self.count += 1

    def write_image(self, topic: str, stamp_ns: int, array: np.ndarray, encoding: str) -> None:
        """One extra sensor_msgs/msg/Image on ``topic`` (e.g. an amplitude image beside the depth).

        The channel is registered on first use. Call it with the frame's stamp, before `write` of
        the same frame, so stamp and sequence number pair it with the depth message.
        """
        if topic not in self._ch:
            self._ch[topic] = self.image_channel(topic)
        self.add_image(self._ch[topic], stamp_ns, stamp_ns, FRAME_ID, array, encoding, self.count)

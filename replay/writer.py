"""The ``--out`` recording: the input, message for message, plus what the model saw.

Why copy everything through: an engineer opens one file in Foxglove and sees the robot's own
topics (depth, camera info, TF, whatever was recorded) next to the segmentation, on the same
timeline. Two new topics, both ``sensor_msgs/msg/Image`` (ROS 2 CDR, which Foxglove displays in
any file), stamped with the depth frame's log time and header stamp and its ``frame_id``:

- ``/depthseg/mask``  mono8 with the raw classes: **0 background, 1 object, 255 unknown**
  (invalid depth: dead, flying or out-of-range pixels). Machine-readable; in an Image panel it
  looks black with white dead pixels. Look at the overlay instead.
- ``/depthseg/overlay`` rgb8 for people: background in grey (brighter = nearer), objects in
  orange shaded by depth, unknown pixels in magenta.

The file is written to a temporary sibling and renamed into place by `close`; if the input is
damaged, the caller still closes, so the output holds everything up to the damage and is a
complete, indexed MCAP. Metadata and attachment records of the input are not copied.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import BinaryIO

import numpy as np
from mcap.records import Channel, Message, Schema
from mcap.writer import CompressionType, Writer

from edge import rosmsg
from edge.errors import DataError
from edge.frames import Frame, atomic_path

__all__ = ["ReplayWriter", "overlay_rgb", "MASK_TOPIC", "OVERLAY_TOPIC", "UNKNOWN", "OBJECT_RGB", "UNKNOWN_RGB"]

MASK_TOPIC = "/depthseg/mask"
OVERLAY_TOPIC = "/depthseg/overlay"
UNKNOWN = 255
OBJECT_RGB = np.array([255, 140, 0], dtype=np.float32)  # orange
UNKNOWN_RGB = np.array([255, 0, 255], dtype=np.uint8)  # magenta


def _lut() -> np.ndarray:
    """[class (0 background, 1 object, 2 unknown), grey level] -> RGB."""
    g = np.arange(256, dtype=np.float32)[:, None]
    lut = np.empty((3, 256, 3), dtype=np.uint8)
    lut[0] = np.repeat(g, 3, axis=1).astype(np.uint8)
    lut[1] = np.clip(0.35 * g + 0.65 * OBJECT_RGB, 0, 255).astype(np.uint8)
    lut[2] = UNKNOWN_RGB
    return lut


_LUT = _lut().reshape(768, 3)  # row = class * 256 + grey


def overlay_rgb(depth: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """H x W x 3 uint8 picture of a mask (0/1/255) over its depth frame (one table lookup)."""
    depth = np.asarray(depth, dtype=np.float32)
    mask = np.asarray(mask)
    if depth.shape != mask.shape:
        raise DataError(f"overlay: depth {depth.shape} and mask {mask.shape} differ in size")
    valid = mask != UNKNOWN
    row = np.zeros(depth.shape, dtype=np.uint16)
    if valid.any():
        d = depth[valid]
        lo, hi = float(d.min()), float(d.max())
        span = hi - lo if hi > lo else 1.0
        # nearer = brighter, 60..220, so the grey never looks like an unknown or a saturated pixel
        row[valid] = (220.0 - 160.0 * (d - lo) / span).astype(np.uint16)
    row[mask == 1] += 256
    row[~valid] = 512
    return _LUT.take(row, axis=0)


class ReplayWriter:
    """Copy a recording's messages and add mask and overlay images; atomic on `close`."""

    def __init__(
        self,
        path: str | Path,
        profile: str = "",
        compression: str = "zstd",
        chunk_size: int = 4 * 1024 * 1024,
        overlay: bool = True,
    ) -> None:
        self.path = Path(path)
        if self.path.is_dir():
            raise DataError(f"{self.path}: is a directory; --out needs a file name such as out.mcap")
        if not self.path.parent.exists():
            raise DataError(f"{self.path.parent}: output directory does not exist")
        comp = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4, "none": CompressionType.NONE}
        if compression not in comp:
            raise DataError(f"unknown compression '{compression}'; choose from {sorted(comp)}")
        self.tmp = atomic_path(self.path)
        self._fh: BinaryIO = open(self.tmp, "wb")
        self._w = Writer(self._fh, chunk_size=chunk_size, compression=comp[compression])
        self._w.start(profile=profile if profile in ("ros2", "") else "", library="depthseg-replay")
        self._schemas: dict[int, int] = {}
        self._channels: dict[int, int] = {}
        img = self._w.register_schema(rosmsg.IMAGE_TYPE, "ros2msg", rosmsg.IMAGE_MSGDEF.encode())
        self._mask_ch = self._w.register_channel(MASK_TOPIC, "cdr", img)
        self._overlay_ch = self._w.register_channel(OVERLAY_TOPIC, "cdr", img) if overlay else None
        self.copied = 0
        self.written = 0
        self._closed = False

    def copy(self, schema: Schema | None, channel: Channel, message: Message) -> None:
        """Pass one input message through unchanged (a `DepthStream.message_hook`)."""
        cid = self._channels.get(channel.id)
        if cid is None:
            sid = 0
            if schema is not None:
                sid = self._schemas.get(schema.id, 0)
                if sid == 0:
                    sid = self._schemas[schema.id] = self._w.register_schema(schema.name, schema.encoding, schema.data)
            cid = self._channels[channel.id] = self._w.register_channel(
                channel.topic, channel.message_encoding, sid, dict(channel.metadata)
            )
        self._w.add_message(
            cid, log_time=message.log_time, data=message.data, publish_time=message.publish_time,
            sequence=message.sequence,
        )
        self.copied += 1

    def write(self, frame: Frame, mask: np.ndarray) -> None:
        """Mask (and overlay) of one frame, on the frame's timestamps."""
        stamp = int(frame.extra.get("header_stamp_ns") or frame.stamp_ns)
        frame_id = str(frame.extra.get("frame_id", ""))
        t = int(frame.stamp_ns)
        seq = self.written
        m = np.ascontiguousarray(mask, dtype=np.uint8)
        self._w.add_message(self._mask_ch, log_time=t, publish_time=t, sequence=seq,
                            data=rosmsg.encode_image(stamp, frame_id, m, "mono8"))
        if self._overlay_ch is not None:
            rgb = overlay_rgb(frame.depth, m)
            self._w.add_message(self._overlay_ch, log_time=t, publish_time=t, sequence=seq,
                                data=rosmsg.encode_image(stamp, frame_id, rgb, "rgb8"))
        self.written += 1

    def close(self) -> None:
        """Finish the index and footer, then rename into place."""
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
        """Drop the partial output (nothing appears under the final name)."""
        if self._closed:
            return
        self._closed = True
        try:
            self._fh.close()
        finally:
            self.tmp.unlink(missing_ok=True)

    def __enter__(self) -> ReplayWriter:
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is None:
            self.close()
        else:
            self.abort()

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

from pathlib import Path

import numpy as np
from mcap.records import Channel, Message, Schema

from edge.errors import DataError
from edge.io.frames import Frame
from edge.io.writer import McapWriter
from edge.metrics import UNKNOWN

__all__ = ["ReplayWriter", "overlay_rgb", "MASK_TOPIC", "OVERLAY_TOPIC", "UNKNOWN", "OBJECT_RGB", "UNKNOWN_RGB"]

MASK_TOPIC = "/depthseg/mask"
OVERLAY_TOPIC = "/depthseg/overlay"
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


class ReplayWriter(McapWriter):
    """Copy a recording's messages and add mask and overlay images; atomic on `close` (`McapWriter`)."""

    def __init__(
        self,
        path: str | Path,
        profile: str = "",
        compression: str = "zstd",
        chunk_size: int = 4 * 1024 * 1024,
        overlay: bool = True,
    ) -> None:
        super().__init__(path, profile=profile if profile in ("ros2", "") else "", library="depthseg-replay",
                         compression=compression, chunk_size=chunk_size)
        self._schemas: dict[int, int] = {}
        self._channels: dict[int, int] = {}
        self._mask_ch = self.image_channel(MASK_TOPIC)
        self._overlay_ch = self.image_channel(OVERLAY_TOPIC) if overlay else None
        self.copied = 0
        self.written = 0

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
        m = np.ascontiguousarray(mask, dtype=np.uint8)
        self.add_image(self._mask_ch, t, stamp, frame_id, m, "mono8", self.written)
        if self._overlay_ch is not None:
            self.add_image(self._overlay_ch, t, stamp, frame_id, overlay_rgb(frame.depth, m), "rgb8", self.written)
        self.written += 1

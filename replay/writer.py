"""The ``--out`` recording: the input, message for message, plus what the model saw.

Why copy everything through: an engineer opens one file in Foxglove and sees the robot's own
topics (depth, camera info, TF, whatever was recorded) next to the segmentation, on the same
timeline. Three new topics under a namespace (``/depthseg`` unless ``--out-namespace`` says
otherwise), all ``sensor_msgs/msg/Image`` (ROS 2 CDR, which Foxglove displays in any file),
stamped with the depth frame's log time and header stamp and its ``frame_id``:

- ``<ns>/mask``  rgb8, the mask as a picture that displays in any image panel: table (background)
  dark blue, objects orange, unknown pixels magenta (`MASK_COLOURS`).
- ``<ns>/mask_raw``  mono8 with the raw classes: **0 background, 1 object, 255 unknown**
  (invalid depth: dead, flying or out-of-range pixels). For programs; it looks black on screen.
- ``<ns>/overlay`` rgb8 for people: background in grey (brighter = nearer), objects in
  orange shaded by depth, unknown pixels in magenta.

The file is written to a temporary sibling and renamed into place by `close`; if the input is
damaged, the caller still closes, so the output holds everything up to the damage and is a
complete, indexed MCAP. Metadata and attachment records of the input are not copied.

A ``ros2``-profile output holds only ROS 2 message types, so ``rosbags`` and ROS 2 tools open it:
a JSON channel of the input (``/depthseg/scene`` in older simulator files) is copied as
``std_msgs/msg/String`` holding the same JSON text; channels in other non-ROS encodings
(protobuf) cannot be expressed there and are left out (counted in ``skipped``).
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
from mcap.records import Channel, Message, Schema

from edge import rosmsg
from edge.errors import ConfigError, DataError
from edge.io.frames import Frame
from edge.io.writer import McapWriter
from edge.metrics import UNKNOWN

__all__ = ["ReplayWriter", "overlay_rgb", "mask_rgb", "output_topics", "check_namespace", "check_output_topics",
           "MASK_TOPIC",
           "MASK_RAW_TOPIC", "OVERLAY_TOPIC", "DEFAULT_NAMESPACE", "UNKNOWN", "OBJECT_RGB", "UNKNOWN_RGB",
           "MASK_COLOURS"]

DEFAULT_NAMESPACE = "/depthseg"
MASK_TOPIC = "/depthseg/mask"
MASK_RAW_TOPIC = "/depthseg/mask_raw"
OVERLAY_TOPIC = "/depthseg/overlay"
OBJECT_RGB = np.array([255, 140, 0], dtype=np.float32)  # orange
UNKNOWN_RGB = np.array([255, 0, 255], dtype=np.uint8)  # magenta


# class -> colour of the displayable mask: background (table) dark blue, object orange, unknown magenta
MASK_COLOURS = np.zeros((256, 3), dtype=np.uint8)
MASK_COLOURS[0] = (30, 60, 150)
MASK_COLOURS[1] = (255, 140, 0)
MASK_COLOURS[2:] = UNKNOWN_RGB
_NAMESPACE_RE = re.compile(r"^(/[A-Za-z][A-Za-z0-9_]*)+$")


def check_namespace(ns: str) -> str:
    """A ROS topic namespace such as ``/depthseg`` or ``/robot1/seg`` (trailing slash dropped)."""
    ns = ns.rstrip("/") if ns not in ("", "/") else ns
    if not _NAMESPACE_RE.match(ns):
        raise ConfigError(
            f"`namespace` '{ns}' is not a ROS namespace; use '/name' or '/a/b' (letters, digits, _; "
            "each part starts with a letter)"
        )
    return ns


def output_topics(namespace: str = DEFAULT_NAMESPACE) -> dict[str, str]:
    """{'mask', 'mask_raw', 'overlay'} -> topic under ``namespace``."""
    ns = check_namespace(namespace)
    return {k: f"{ns}/{k}" for k in ("mask", "mask_raw", "overlay")}


def check_output_topics(input_topics, namespace: str = DEFAULT_NAMESPACE) -> None:
    """Refuse a namespace whose output topics the input already has (`ConfigError`, one line).

    Why refuse rather than rename: replaying a replay's output into the same namespace would put
    two channels on ``/depthseg/mask`` (the old mask and the new one) and a viewer would show
    either. The user picks the namespace (`namespace`), so the output never surprises.
    """
    ns = check_namespace(namespace)
    clash = sorted(set(output_topics(ns).values()) & set(input_topics))
    if clash:
        free = next(f"{ns}{i}" for i in range(2, 1000)
                    if not set(output_topics(f"{ns}{i}").values()) & set(input_topics))
        raise ConfigError(
            f"the recording already has {', '.join(clash)} (is it a replay output?); the output would hold "
            f"two channels on one topic: choose another `namespace`, e.g. {free}"
        )


def mask_rgb(mask: np.ndarray) -> np.ndarray:
    """H x W x 3 uint8 picture of a mask (0 background, 1 object, 255 unknown); see `MASK_COLOURS`."""
    return MASK_COLOURS.take(np.asarray(mask, dtype=np.uint8), axis=0)


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
        namespace: str = DEFAULT_NAMESPACE,
    ) -> None:
        self.topics = output_topics(namespace)  # before the file exists: a bad namespace leaves nothing behind
        self.namespace = check_namespace(namespace)
        self._own = frozenset(self.topics.values())
        self.profile = profile if profile in ("ros2", "") else ""
        super().__init__(path, profile=self.profile, library="depthseg-replay",
                         compression=compression, chunk_size=chunk_size)
        self._schemas: dict[int, int] = {}
        self._channels: dict[int, int] = {}
        self._mask_ch = self.image_channel(self.topics["mask"])
        self._mask_raw_ch = self.image_channel(self.topics["mask_raw"])
        self._overlay_ch = self.image_channel(self.topics["overlay"]) if overlay else None
        self.copied = 0
        self.skipped = 0
        self._string_schema = 0
        self.written = 0

    def copy(self, schema: Schema | None, channel: Channel, message: Message) -> None:
        """Pass one input message through unchanged (a `DepthStream.message_hook`).

        Raises `ConfigError` when the input has a topic this writer adds (`check_output_topics`).
        """
        cid = self._channels.get(channel.id)
        if cid is None and channel.topic in self._own:
            check_output_topics([channel.topic], self.namespace)
        data = message.data
        if self.profile == "ros2" and channel.message_encoding != "cdr":
            if channel.message_encoding != "json":
                self.skipped += 1
                return
            data = rosmsg.encode_string(bytes(data).decode(errors="replace"))
            if cid is None:
                if not self._string_schema:
                    self._string_schema = self._w.register_schema(
                        rosmsg.STRING_TYPE, "ros2msg", rosmsg.STRING_MSGDEF.encode()
                    )
                cid = self._channels[channel.id] = self._w.register_channel(
                    channel.topic, "cdr", self._string_schema, {"content": "application/json"}
                )
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
            cid, log_time=message.log_time, data=data, publish_time=message.publish_time,
            sequence=message.sequence,
        )
        self.copied += 1

    def write(self, frame: Frame, mask: np.ndarray) -> None:
        """Mask (and overlay) of one frame, on the frame's timestamps.

        The header stamp is the depth frame's; when that is 0 (no stamp) its log time, if a ROS 2
        header can hold it (int32 seconds end in 2038), else 0 like the input's.
        """
        stamp = int(frame.extra.get("header_stamp_ns") or frame.stamp_ns)
        if not rosmsg.stamp_fits(stamp):
            stamp = 0
        frame_id = str(frame.extra.get("frame_id", ""))
        t = int(frame.stamp_ns)
        m = np.ascontiguousarray(mask, dtype=np.uint8)
        self.add_image(self._mask_ch, t, stamp, frame_id, mask_rgb(m), "rgb8", self.written)
        self.add_image(self._mask_raw_ch, t, stamp, frame_id, m, "mono8", self.written)
        if self._overlay_ch is not None:
            self.add_image(self._overlay_ch, t, stamp, frame_id, overlay_rgb(frame.depth, m), "rgb8", self.written)
        self.written += 1

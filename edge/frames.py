"""Depth frames in and out of MCAP: the layout ``depthseg-sim`` writes and every tool reads.

Layout (one message of each per frame, all with the frame's timestamp as log time):
- ``/pico_flexx/image_depth``  sensor_msgs/msg/Image 32FC1, metres (Z), 0 = invalid
- ``/pico_flexx/labels``       sensor_msgs/msg/Image mono8, 1 = object, 0 = background
- ``/pico_flexx/camera_info``  sensor_msgs/msg/CameraInfo
- ``/depthseg/clean_depth``    sensor_msgs/msg/Image 32FC1, noise-free Z (simulated data only)
- ``/depthseg/scene``          JSON: frame index, seed and scene parameters (regenerate from it)

Readers stream (generators), never load a whole file. Numpy + mcap only (edge path).
"""

from __future__ import annotations

import json
import os
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, BinaryIO

import numpy as np
from mcap.reader import make_reader
from mcap.writer import CompressionType, Writer

from edge import rosmsg
from edge.errors import DataError

__all__ = [
    "TOPIC_DEPTH",
    "TOPIC_LABELS",
    "TOPIC_INFO",
    "TOPIC_CLEAN",
    "TOPIC_SCENE",
    "FRAME_ID",
    "Frame",
    "FrameWriter",
    "list_mcap_files",
    "atomic_path",
    "atomic_write",
    "write_bytes_atomic",
]

TOPIC_DEPTH = "/pico_flexx/image_depth"
TOPIC_LABELS = "/pico_flexx/labels"
TOPIC_INFO = "/pico_flexx/camera_info"
TOPIC_CLEAN = "/depthseg/clean_depth"
TOPIC_SCENE = "/depthseg/scene"
FRAME_ID = "pico_flexx_optical_frame"

_SCENE_SCHEMA = json.dumps(
    {
        "title": "depthseg/Scene",
        "type": "object",
        "properties": {"index": {"type": "integer"}, "seed": {"type": "array"}, "params": {"type": "object"}},
    }
).encode()


@dataclass
class Frame:
    """One depth frame and what came with it."""

    depth: np.ndarray  # float32 H x W, metres; invalid may be 0, NaN, negative or inf
    stamp_ns: int
    label: np.ndarray | None = None  # uint8 H x W, 1 = object
    clean: np.ndarray | None = None  # float32 H x W, noise-free depth (simulation only)
    info: dict[str, Any] | None = None  # CameraInfo fields (fx, fy, cx, cy, d, ...)
    scene: dict[str, Any] | None = None
    topic: str = TOPIC_DEPTH
    extra: dict[str, Any] = field(default_factory=dict)


def atomic_path(path: Path) -> Path:
    """Temporary sibling of ``path``: write there, then ``os.replace`` it into place."""
    return path.with_name(f".{path.name}.{os.getpid()}.tmp")


@contextmanager
def atomic_write(path: str | Path) -> Iterator[Path]:
    """Yield a temporary path to write; it replaces ``path`` only if the block succeeds.

    Why: an interrupted write must never destroy what was there before (a checkpoint, a model,
    a figure), and a reader must never see half a file under the final name.
    """
    path = Path(path)
    tmp = atomic_path(path)
    try:
        yield tmp
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)


def write_bytes_atomic(path: str | Path, data: bytes) -> Path:
    with atomic_write(path) as tmp:
        tmp.write_bytes(data)
    return Path(path)


class FrameWriter:
    """Write frames in the depthseg layout; the file appears under its name only when complete.

    Use as a context manager. On an exception the temporary file is removed, so a reader never
    sees a partial file under the final name (a resumed run regenerates it).
    """

    def __init__(self, path: str | Path, compression: str = "zstd", chunk_size: int = 4 * 1024 * 1024) -> None:
        self.path = Path(path)
        self.tmp = atomic_path(self.path)
        comp = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4, "none": CompressionType.NONE}
        if compression not in comp:
            raise DataError(f"unknown compression '{compression}'; choose from {sorted(comp)}")
        self._fh: BinaryIO = open(self.tmp, "wb")
        self._w = Writer(self._fh, chunk_size=chunk_size, compression=comp[compression])
        self._w.start(profile="ros2", library="depthseg")
        img = self._w.register_schema(rosmsg.IMAGE_TYPE, "ros2msg", rosmsg.IMAGE_MSGDEF.encode())
        info = self._w.register_schema(rosmsg.CAMERA_INFO_TYPE, "ros2msg", rosmsg.CAMERA_INFO_MSGDEF.encode())
        scene = self._w.register_schema("depthseg/Scene", "jsonschema", _SCENE_SCHEMA)
        self._image_schema = img
        self._ch = {
            TOPIC_DEPTH: self._w.register_channel(TOPIC_DEPTH, "cdr", img),
            TOPIC_LABELS: self._w.register_channel(TOPIC_LABELS, "cdr", img),
            TOPIC_INFO: self._w.register_channel(TOPIC_INFO, "cdr", info),
            TOPIC_CLEAN: self._w.register_channel(TOPIC_CLEAN, "cdr", img),
            TOPIC_SCENE: self._w.register_channel(TOPIC_SCENE, "json", scene),
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
        t = int(stamp_ns)

        def add(topic: str, data: bytes) -> None:
            self._w.add_message(self._ch[topic], log_time=t, publish_time=t, data=data, sequence=self.count)

        depth = np.asarray(depth, dtype=np.float32)
        if intrinsics is not None:
            fx, fy, cx, cy = intrinsics
            h, w = depth.shape
            add(TOPIC_INFO, rosmsg.encode_camera_info(t, FRAME_ID, w, h, fx, fy, cx, cy, distortion))
        add(TOPIC_DEPTH, rosmsg.encode_image(t, FRAME_ID, depth, "32FC1"))
        if label is not None:
            add(TOPIC_LABELS, rosmsg.encode_image(t, FRAME_ID, np.asarray(label, dtype=np.uint8), "mono8"))
        if clean is not None:
            add(TOPIC_CLEAN, rosmsg.encode_image(t, FRAME_ID, np.asarray(clean, dtype=np.float32), "32FC1"))
        if scene is not None:
            add(TOPIC_SCENE, json.dumps(scene, sort_keys=True).encode())
        self.count += 1

    def write_image(self, topic: str, stamp_ns: int, array: np.ndarray, encoding: str) -> None:
        """One extra sensor_msgs/msg/Image on ``topic`` (e.g. an amplitude image beside the depth).

        The channel is registered on first use. Call it with the frame's stamp, before `write` of
        the same frame, so stamp and sequence number pair it with the depth message.
        """
        if topic not in self._ch:
            self._ch[topic] = self._w.register_channel(topic, "cdr", self._image_schema)
        t = int(stamp_ns)
        data = rosmsg.encode_image(t, FRAME_ID, np.asarray(array), encoding)
        self._w.add_message(self._ch[topic], log_time=t, publish_time=t, data=data, sequence=self.count)

    def close(self) -> None:
        self._w.finish()
        self._fh.flush()
        os.fsync(self._fh.fileno())
        self._fh.close()
        os.replace(self.tmp, self.path)

    def abort(self) -> None:
        try:
            self._fh.close()
        finally:
            self.tmp.unlink(missing_ok=True)

    def __enter__(self) -> FrameWriter:
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is None:
            self.close()
        else:
            self.abort()


def list_mcap_files(path: str | Path) -> list[Path]:
    """One .mcap file, or the complete .mcap files of a directory (sorted; temp files skipped)."""
    p = Path(path)
    if not p.exists():
        raise DataError(f"{p}: no such file or directory")
    if p.is_dir():
        files = sorted(f for f in p.glob("*.mcap") if not f.name.startswith("."))
        if not files:
            raise DataError(f"{p}: directory holds no .mcap files; generate some with depthseg-sim --out {p}")
        return files
    return [p]


def _decode_depth(msg_data: bytes, topic: str) -> np.ndarray:
    img = rosmsg.decode_image(msg_data, what=f"{topic}")
    arr = rosmsg.image_to_array(img, what=f"{topic}")
    if img.encoding in ("16UC1", "mono16"):
        return arr.astype(np.float32) / 1000.0  # REP 118: millimetres, 0 invalid
    if img.encoding in ("32FC1", "64FC1"):
        return arr.astype(np.float32, copy=False)
    raise DataError(f"{topic}: pixel encoding '{img.encoding}' is not depth; expected 32FC1 or 16UC1")


def _flush(group: dict[str, Any], t: int, info: dict[str, Any] | None, topic: str) -> Iterator[Frame]:
    """The frame collected for log time ``t`` (if it had a depth image); empties ``group``."""
    if "depth" in group:
        yield Frame(depth=group["depth"], stamp_ns=int(t), label=group.get("label"), clean=group.get("clean"),
                    info=info, scene=group.get("scene"), topic=topic)
    group.clear()


def iter_frames(
    path: str | Path,
    depth_topic: str | None = None,
    labels_topic: str | None = None,
    with_clean: bool = False,
) -> Iterator[Frame]:
    """Stream frames (with labels where present) from one MCAP file or a directory of them.

    Simple reader for the depthseg layout and plain ROS 2 Image topics; `replay.reader`
    has the general one (foxglove images, damaged files, topic auto-detection).
    """
    dt = depth_topic or TOPIC_DEPTH
    lt = labels_topic or TOPIC_LABELS
    topics = [dt, lt, TOPIC_INFO, TOPIC_SCENE] + ([TOPIC_CLEAN] if with_clean else [])
    for f in list_mcap_files(path):
        with open(f, "rb") as fh:
            info = None
            group: dict[str, Any] = {}
            group_t: int | None = None

            # All messages of one frame share its log time (the layout above), so a frame is
            # complete as soon as a message with a later time arrives.
            for _schema, channel, message in make_reader(fh).iter_messages(topics=topics):
                t = message.log_time
                if group_t is not None and t != group_t:
                    yield from _flush(group, group_t, info, dt)
                group_t = t
                if channel.topic == TOPIC_INFO:
                    info = rosmsg.decode_camera_info(message.data)
                elif channel.topic == TOPIC_SCENE:
                    group["scene"] = json.loads(message.data)
                elif channel.topic == TOPIC_CLEAN:
                    group["clean"] = _decode_depth(message.data, channel.topic)
                elif channel.topic == dt:
                    group["depth"] = _decode_depth(message.data, dt)
                elif channel.topic == lt:
                    img = rosmsg.decode_image(message.data, what=lt)
                    group["label"] = (rosmsg.image_to_array(img, what=lt) > 0).astype(np.uint8)
            if group_t is not None:
                yield from _flush(group, group_t, info, dt)

"""Depth frames in and out of MCAP: the layout ``depthseg-sim`` writes and every tool reads.

Layout (one message of each per frame, all with the frame's timestamp as log time):
- ``/pico_flexx/image_depth``  sensor_msgs/msg/Image 32FC1, metres (Z), 0 = invalid
- ``/pico_flexx/labels``       sensor_msgs/msg/Image mono8, 1 = object, 0 = background
- ``/pico_flexx/camera_info``  sensor_msgs/msg/CameraInfo
- ``/depthseg/clean_depth``    sensor_msgs/msg/Image 32FC1, noise-free Z (simulated data only)
- ``/depthseg/scene``          std_msgs/msg/String holding JSON: frame index, seed and scene
  parameters (regenerate from it). Older files carry it as a JSON channel; readers
  accept both. Only ROS 2 message types, so ``rosbags`` and ROS 2 tools open the files.

Stamps: the simulator and importers stamp frame i at ``SIM_EPOCH_NS + i * period`` (a fixed,
real date, so tools that show wall-clock time do not show 1970, and output stays deterministic).

`edge.io.reader` reads it (and any other ROS 2 / Foxglove recording), `edge.io.writer` writes it.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from edge import rosmsg
from edge.errors import McapDataError

__all__ = [
    "TOPIC_DEPTH",
    "TOPIC_LABELS",
    "TOPIC_INFO",
    "TOPIC_CLEAN",
    "TOPIC_SCENE",
    "FRAME_ID",
    "SIM_EPOCH_NS",
    "Frame",
    "decode_scene",
]

TOPIC_DEPTH = "/pico_flexx/image_depth"
TOPIC_LABELS = "/pico_flexx/labels"
TOPIC_INFO = "/pico_flexx/camera_info"
TOPIC_CLEAN = "/depthseg/clean_depth"
TOPIC_SCENE = "/depthseg/scene"
FRAME_ID = "pico_flexx_optical_frame"
SIM_EPOCH_NS = 1_704_067_200 * 1_000_000_000  # 2024-01-01T00:00:00Z: simulated frame 0


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


def decode_scene(message_encoding: str, data: bytes) -> dict[str, Any]:
    """The scene dict of a ``/depthseg/scene`` message (std_msgs/String CDR, or JSON in older files).

    Raises `McapDataError` (one line) when the message is not a JSON object.
    """
    try:
        text = rosmsg.decode_string(data, TOPIC_SCENE) if message_encoding == "cdr" else bytes(data).decode()
        scene = json.loads(text)
    except (ValueError, RecursionError) as exc:  # bad UTF-8, bad JSON, nesting too deep
        raise McapDataError(f"{TOPIC_SCENE}: scene message is not JSON ({type(exc).__name__}: {str(exc)[:120]})") from None
    if not isinstance(scene, dict):
        raise McapDataError(f"{TOPIC_SCENE}: scene message is a JSON {type(scene).__name__}, not an object")
    return scene

"""Stream depth frames out of any recording: MCAP (ROS 2 bags, Foxglove, our simulations), ROS 1/2 bags.

Why a reader of our own instead of ``mcap.reader.make_reader(...).iter_messages()``:

- **Bounded memory.** The non-seeking reader sorts by log time, which loads the whole file, and
  the seeking one needs an intact summary. We walk the records in file order (recorders write in
  arrival order), one chunk at a time, so a recording of any length streams in constant memory.
- **Damage is expected.** Robots lose power mid-recording. A truncated or corrupt file is read
  up to the damage (chunk CRCs are checked, record lengths are clamped to the file), the frames
  before it are delivered, and then one `McapDataError` says where and what broke.
- **The user should not need to know the topic.** The depth topic is found from the schemas
  (``sensor_msgs/msg/Image``, ``foxglove.RawImage``), the pixel encoding of its first message
  (32FC1 metres, 16UC1 millimetres; REP 118) and the topic name; when that is ambiguous or
  empty, the error lists the candidates so ``--topic`` is one copy-paste away.

Decoders: ROS 2 CDR through `edge.rosmsg` (size-checked against height x step before any pixel is
trusted), foxglove ``RawImage`` in protobuf (schema = FileDescriptorSet, `mcap_protobuf`) and in
JSON (``data`` base64, as Foxglove writes it), and ``sensor_msgs/CompressedImage`` compressedDepth
(`edge.io.compressed`). Invalid depth pixels (0, NaN, negative, inf) are passed through untouched:
`edge.preprocess` owns what counts as invalid.

ROS 1 ``.bag``, ROS 2 ``.db3`` and ROS 2 bag directories are not a second reader: `edge.io.bags`
turns them into the same (schema, channel, message) records that the MCAP walk yields, so topic
detection, pairing, decoding and errors are this module's for every format.

Labels (mono8, nonzero = object) are paired with depth frames by header timestamp (log time when
the header stamp is 0) within a tolerance, looking at most ``window`` frames ahead.
"""

from __future__ import annotations

import base64
import binascii
import json
import logging
import math
import os
import re
import struct
from collections import deque
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from mcap.records import Channel, Chunk, Header, Message, Schema
from mcap.stream_reader import MAGIC_SIZE, CRCValidationError, StreamReader, breakup_chunk

from edge import rosmsg
from edge.errors import ConfigError, DataError, DepthsegError, McapDataError
from edge.io.bags import bag_kind, is_bag, open_bag
from edge.io.chunks import (
    MAX_CHUNK_BYTES,
    _check_bag_chunks,
    _check_ros1_chunks,
    _ClampedFile,
    _Damage,
    _decompress_chunk,
)
from edge.io.compressed import COMPRESSED_IMAGE_TYPES, decode_compressed_image, decompress_depth
from edge.io.frames import TOPIC_CLEAN, TOPIC_SCENE, Frame, decode_scene
from edge.io.paths import check_input_file
from edge.preprocess import valid_mask

__all__ = [
    "DepthStream",
    "open_depth_stream",
    "DEPTH_ENCODINGS",
    "LABEL_ENCODINGS",
    "MessageHook",
    "list_mcap_files",
    "open_frames",
    "iter_frames",
]

MCAP_MAGIC = b"\x89MCAP0\r\n"
# pixel encoding -> metres per unit. mono16 only when chosen with --topic (the pico flexx
# driver publishes its grey image as mono16, so it is never auto-detected as depth).
DEPTH_ENCODINGS: dict[str, float] = {"32FC1": 1.0, "64FC1": 1.0, "16UC1": 0.001, "mono16": 0.001}
AUTO_DEPTH_ENCODINGS = frozenset({"32FC1", "64FC1", "16UC1"})
LABEL_ENCODINGS = frozenset({"mono8", "8UC1"})

ROS_IMAGE_TYPES = frozenset({"sensor_msgs/msg/Image", "sensor_msgs/Image"})
FOXGLOVE_IMAGE_TYPES = frozenset({"foxglove.RawImage", "foxglove_msgs/msg/RawImage"})
CAMERA_INFO_TYPES = frozenset({"sensor_msgs/msg/CameraInfo", "sensor_msgs/CameraInfo"})
# name tokens of 32FC1 topics that are not the depth image (noise sigma, our noise-free copy...)
_NOT_DEPTH_TOKENS = frozenset(
    {"clean", "noise", "label", "labels", "mask", "conf", "confidence", "amplitude", "intensity",
     "ir", "gray", "grey", "overlay", "sigma", "std", "disparity", "depthseg"}
)
_DECODABLE = {"cdr": "ROS 2 CDR", "protobuf": "protobuf", "json": "JSON"}

PEEK_BYTES = 64 * 1024 * 1024  # how far to look for the first message of each image topic
# A chunk is decompressed only up to the size its header declares, and never beyond this bound
# (raised with the frame limit: twice the largest allowed 64FC1 frame): a few kB of zeros can
# claim to be a gigabyte. Real recorders write chunks of a few MB.
DEFAULT_MAX_FRAME = (4096, 4096)  # width, height: generous for any depth camera (ToF: 224x172 .. 1280x720)
MM_MEDIAN_M = 10.0  # a 32FC1 frame whose valid median is farther than this is not metres from a ToF camera
DEFAULT_WINDOW = 32  # frames a depth frame may wait for its label
DEFAULT_TOLERANCE_NS = 1_000_000  # 1 ms: labels share the depth header stamp in practice
EXTRA_TOPICS = {"clean": TOPIC_CLEAN, "scene": TOPIC_SCENE}  # what the simulator records beside each frame

MessageHook = Callable[[Schema | None, Channel, Message], None]
_log = logging.getLogger(__name__)


def _check_max_frame(max_frame: Any) -> tuple[int, int]:
    try:
        w, h = max_frame
        ok = all(isinstance(v, int) and not isinstance(v, bool) and v > 0 for v in (w, h))
    except (TypeError, ValueError):
        ok = False
    if not ok:
        raise ConfigError(f"`max_frame` must be (width, height) in pixels, two positive integers; got {max_frame!r}")
    return int(w), int(h)


@dataclass
class _TopicInfo:
    topic: str
    schema_name: str
    schema_encoding: str
    message_encoding: str
    channel_ids: list[int] = field(default_factory=list)
    first_encoding: str | None = None  # pixel encoding of the first message seen
    first_size: tuple[int, int] | None = None
    peek_error: str | None = None
    n_messages: int | None = None  # from the summary statistics; None when unknown

    @property
    def kind(self) -> str:
        if self.schema_name in ROS_IMAGE_TYPES or self.schema_name in FOXGLOVE_IMAGE_TYPES:
            return "image"
        if self.schema_name.endswith("RawImage") or self.schema_name in COMPRESSED_IMAGE_TYPES:
            return "image"
        if self.schema_name in CAMERA_INFO_TYPES:
            return "info"
        if self.schema_name.endswith("CameraCalibration") and self.message_encoding in ("json", "protobuf"):
            return "info"  # foxglove.CameraCalibration: K, D, width, height
        return "other"

    def describe(self) -> str:
        bits = [self.schema_name or "(no schema)"]
        if self.first_encoding:
            bits.append(self.first_encoding)
        if self.first_size:
            bits.append(f"{self.first_size[1]}x{self.first_size[0]}")
        if self.message_encoding not in _DECODABLE:
            bits.append(f"message encoding '{self.message_encoding}'")
        if self.peek_error:
            bits.append(f"unreadable: {self.peek_error.split(': ', 1)[-1][:100]}")
        elif self.kind == "image" and self.first_encoding is None:
            bits.append("no messages" if self.n_messages == 0 else "no messages seen")
        return f"{self.topic} ({', '.join(bits)})"


def _describe_exc(exc: BaseException) -> str:
    name = type(exc).__name__
    if name == "EndOfFile":
        return "the file ends in the middle of a record (truncated recording?)"
    if name == "InvalidMagic":
        return "bad MCAP magic bytes (not the end of a complete MCAP file)"
    if isinstance(exc, CRCValidationError):
        return f"checksum mismatch ({exc}): the data is corrupt"
    if name == "RecordLengthLimitExceeded":
        return f"record length exceeds the file ({exc}): truncated recording or corrupt data"
    text = str(exc).strip() or name
    return f"unreadable record ({name}: {text[:160]})"


def _walk(
    path: Path,
    size: int,
    schemas: dict[int, Schema],
    channels: dict[int, Channel],
    header_out: list[Header] | None = None,
    position: list[int] | None = None,
    chunk_limit: int = MAX_CHUNK_BYTES,
) -> Iterator[tuple[Schema | None, Channel, Message]]:
    """Messages in file order; `_Damage` at the first record that cannot be read.

    A schema or channel id defined twice with different content is damage too: following the
    second definition would route one topic's messages into another (a String into an Image
    channel); identical repeats (one per chunk, and the summary's) are normal.
    """
    with open(path, "rb") as raw:
        fh = _ClampedFile(raw, size)
        reader = StreamReader(fh, emit_chunks=True, validate_crcs=True, record_size_limit=size)
        records = reader.records
        while True:
            start = fh.pos
            try:
                rec = next(records)
            except StopIteration:
                return
            except DepthsegError:
                raise
            except Exception as exc:  # any parse failure of third-party code is damage, by design
                raise _Damage(start, _describe_exc(exc)) from None
            if position is not None:
                position[0] = fh.pos
            if isinstance(rec, Chunk):
                data = _decompress_chunk(rec, start, chunk_limit)
                try:
                    inner = breakup_chunk(
                        Chunk(compression="", data=data, message_end_time=rec.message_end_time,
                              message_start_time=rec.message_start_time, uncompressed_crc=rec.uncompressed_crc,
                              uncompressed_size=len(data)),
                        validate_crc=True,
                    )
                except Exception as exc:
                    raise _Damage(start, "chunk " + _describe_exc(exc)) from None
                del data
            else:
                inner = (rec,)
            for r in inner:
                if isinstance(r, Message):
                    ch = channels.get(r.channel_id)
                    if ch is None:
                        raise _Damage(start, f"message refers to channel id {r.channel_id}, which is never defined")
                    yield (schemas.get(ch.schema_id) if ch.schema_id else None), ch, r
                elif isinstance(r, Schema):
                    _define(schemas, r, start)
                elif isinstance(r, Channel):
                    _define(channels, r, start)
                elif isinstance(r, Header) and header_out is not None:
                    header_out.append(r)



def _describe_record(r: Schema | Channel) -> str:
    if isinstance(r, Schema):
        return f"'{r.name}' ({r.encoding})"
    return f"{r.topic} ({r.message_encoding}, schema {r.schema_id})"


def _define(table: dict, rec: Schema | Channel, offset: int) -> None:
    """Record a schema or channel; a conflicting redefinition of its id is `_Damage`."""
    old = table.get(rec.id)
    if old is not None:
        if isinstance(rec, Schema):
            same = (old.name, old.encoding, bytes(old.data)) == (rec.name, rec.encoding, bytes(rec.data))
        else:
            same = (old.topic, old.message_encoding, old.schema_id) == (rec.topic, rec.message_encoding, rec.schema_id)
        if not same:
            kind = "schema" if isinstance(rec, Schema) else "channel"
            raise _Damage(
                offset, f"{kind} id {rec.id} is redefined: {_describe_record(old)} became {_describe_record(rec)}; "
                "a recording gives each id one meaning"
            )
        return
    table[rec.id] = rec


def _ros_image(data: bytes, what: str) -> rosmsg.RosImage:
    return rosmsg.decode_image(data, what=what)


def _json_int(d: dict, key: str, what: str, default: int | None = None) -> int:
    """A JSON field that must be a whole number (1e400 parses as inf, "12" is a string: both refused)."""
    v = d.get(key, default)
    if v is None:
        raise McapDataError(f"{what}: not a foxglove RawImage JSON message (no '{key}')")
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v != int(v):
        raise McapDataError(f"{what}: RawImage JSON field '{key}' must be a whole number, got {str(v)[:40]}")
    return int(v)


def _json_image(data: bytes, what: str) -> rosmsg.RosImage:
    try:
        d = json.loads(bytes(data))
        if not isinstance(d, dict):
            raise TypeError(f"top level is a {type(d).__name__}, not an object")
        ts = d.get("timestamp") or {}
        if not isinstance(ts, dict):
            raise TypeError("'timestamp' is not an object")
        sec = _json_int(ts, "sec", what, 0)
        nsec = _json_int(ts, "nsec", what, ts.get("nanosec", 0))
        h, w, step = (_json_int(d, k, what) for k in ("height", "width", "step"))
        if not isinstance(d.get("data"), str):
            raise KeyError("data")
        raw = base64.b64decode(d["data"], validate=True)
        return rosmsg.RosImage(
            sec * 1_000_000_000 + nsec, str(d.get("frame_id", "")), h, w, str(d["encoding"]), 0, step, memoryview(raw),
        )
    except (ValueError, KeyError, TypeError, AttributeError, RecursionError, binascii.Error) as exc:
        raise McapDataError(f"{what}: not a foxglove RawImage JSON message ({type(exc).__name__}: {exc})") from None


def _protobuf_class(schema: Schema, topic: str):
    from mcap_protobuf.decoder import DecoderFactory

    try:
        dec = DecoderFactory().decoder_for("protobuf", schema)
    except Exception as exc:  # a broken FileDescriptorSet raises whatever protobuf raises
        raise McapDataError(
            f"{topic}: protobuf schema '{schema.name}' cannot be loaded ({type(exc).__name__}: {exc}); "
            "the schema data must be a serialized FileDescriptorSet"
        ) from None
    if dec is None:
        raise McapDataError(f"{topic}: schema '{schema.name}' has encoding '{schema.encoding}', expected 'protobuf'")
    return dec


def _protobuf_image(decode, data: bytes, what: str) -> rosmsg.RosImage:
    try:
        m = decode(data)
        ts = m.timestamp
        return rosmsg.RosImage(
            int(ts.seconds) * 1_000_000_000 + int(ts.nanos), m.frame_id, int(m.height), int(m.width),
            m.encoding, 0, int(m.step), memoryview(m.data),
        )
    except DepthsegError:
        raise
    except Exception as exc:
        raise McapDataError(f"{what}: not a foxglove.RawImage protobuf message ({type(exc).__name__}: {exc})") from None


_CV_DISTORTION_LENGTHS = (4, 5, 8, 12, 14)  # what OpenCV's undistortion accepts


def _info_number(v: Any, name: str, what: str) -> float:
    if isinstance(v, (bool, str, bytes)) or v is None:
        raise McapDataError(f"{what}: camera calibration {name} must be a number, got {str(v)[:40]!r}")
    try:
        f = float(v)
    except (TypeError, ValueError, OverflowError):
        raise McapDataError(f"{what}: camera calibration {name} must be a number, got {str(v)[:40]!r}") from None
    if not math.isfinite(f):
        raise McapDataError(f"{what}: camera calibration {name} is {f}, not a finite number")
    return f


def _checked_info(info: dict[str, Any], k: Any, d: Any, what: str) -> dict[str, Any]:
    """CameraInfo fields as numbers a consumer can use, or one `McapDataError` line.

    K must be 9 finite numbers (a string is not a list of digits). The distortion is padded with
    zeros to the next length OpenCV understands (ROS plumb_bob order k1 k2 p1 p2 k3: the missing
    higher terms are zero), so a CameraInfo with 3 coefficients undistorts instead of crashing.
    """
    if isinstance(k, (str, bytes)) or not hasattr(k, "__len__") or len(k) != 9:
        raise McapDataError(f"{what}: camera calibration K must be 9 numbers, got {str(k)[:60]!r}")
    if isinstance(d, (str, bytes)) or not hasattr(d, "__len__"):
        raise McapDataError(f"{what}: camera calibration D must be a list of numbers, got {str(d)[:60]!r}")
    kk = [_info_number(v, "K", what) for v in k]
    dd = [_info_number(v, "D", what) for v in d]
    if len(dd) > _CV_DISTORTION_LENGTHS[-1]:
        raise McapDataError(f"{what}: {len(dd)} distortion coefficients; at most {_CV_DISTORTION_LENGTHS[-1]} exist")
    if dd:
        dd += [0.0] * (min(n for n in _CV_DISTORTION_LENGTHS if n >= len(dd)) - len(dd))
    h, w = (_info_number(info.get(x, 0), x, what) for x in ("height", "width"))
    if h < 0 or w < 0 or h != int(h) or w != int(w):
        raise McapDataError(f"{what}: camera calibration size {w}x{h} is not a whole number of pixels")
    return {
        "frame_id": str(info.get("frame_id", "")), "height": int(h), "width": int(w),
        "distortion_model": str(info.get("distortion_model", "")), "d": dd,
        "fx": kk[0], "fy": kk[4], "cx": kk[2], "cy": kk[5],
    }


def _camera_info(decode_obj, data: bytes, what: str) -> dict[str, Any]:
    kind, dec = decode_obj
    if kind == "cdr":
        ci = rosmsg.decode_camera_info(data, what=what)
        return _checked_info(ci, [ci["fx"], 0, ci["cx"], 0, ci["fy"], ci["cy"], 0, 0, 1], ci["d"], what)
    try:
        m = json.loads(bytes(data)) if kind == "json" else dec(data)
        if kind == "json" and not isinstance(m, dict):
            raise TypeError(f"top level is a {type(m).__name__}, not an object")
        get = (lambda k, d=None: m.get(k, d)) if kind == "json" else (lambda k, d=None: getattr(m, k, d))
        k = get("K") or get("k") or []
        d = get("D") or get("d") or []
        fields = {x: get(x, 0 if x in ("height", "width") else "") for x in ("frame_id", "height", "width", "distortion_model")}
    except DepthsegError:
        raise
    except Exception as exc:
        raise McapDataError(f"{what}: unreadable camera calibration ({type(exc).__name__}: {exc})") from None
    return _checked_info(fields, k if kind == "json" else list(k), d if kind == "json" else list(d), what)


def check_frame_size(width: int, height: int, max_frame: tuple[int, int], what: str) -> None:
    """Refuse a frame larger than ``max_frame`` (width, height) before any pixel is allocated."""
    mw, mh = max_frame
    if width > mw or height > mh:
        raise McapDataError(
            f"{what}: frame is {width}x{height}, larger than the {mw}x{mh} limit (`max_frame`); "
            "raise the limit if the camera really is that large"
        )


class _ChannelDecoder:
    """Turns the raw bytes of one channel into a `rosmsg.RosImage` (or CameraInfo dict); built once per channel."""

    def __init__(self, schema: Schema | None, channel: Channel, max_frame: tuple[int, int] = DEFAULT_MAX_FRAME) -> None:
        self.topic = channel.topic
        self.max_frame = max_frame
        enc = channel.message_encoding
        name = schema.name if schema else ""
        if enc not in _DECODABLE:
            raise McapDataError(
                f"{channel.topic}: message encoding '{enc}' cannot be decoded; supported: "
                + ", ".join(f"{k} ({v})" for k, v in _DECODABLE.items())
                + ("; convert ROS 1 bags with `rosbags-convert`" if enc == "ros1" else "")
            )
        self.kind = "info" if name in CAMERA_INFO_TYPES or name.endswith("CameraCalibration") else "image"
        self.enc = enc
        self._proto = None
        if enc == "protobuf":
            if schema is None:
                raise McapDataError(f"{channel.topic}: protobuf channel without a schema cannot be decoded")
            self._proto = _protobuf_class(schema, channel.topic)
        elif enc == "cdr" and self.kind == "image" and name not in ROS_IMAGE_TYPES | COMPRESSED_IMAGE_TYPES:
            raise McapDataError(
                f"{channel.topic}: CDR messages of type '{name}' are not supported; depth must be "
                "sensor_msgs/msg/Image, sensor_msgs/msg/CompressedImage (compressedDepth) or foxglove.RawImage"
            )
        self.compressed = name in COMPRESSED_IMAGE_TYPES

    def image(self, data: bytes, what: str, check_size: bool = True) -> rosmsg.RosImage:
        """The image header and pixel bytes; its size is checked against ``max_frame`` first.

        ``check_size=False`` (topic detection: only the header is looked at) skips the check for
        raw images; a compressed image is always checked, since it is decoded here.
        """
        if self.enc == "cdr" and self.compressed:
            c = decode_compressed_image(data, what)
            arr, pix = decompress_depth(c, what, max_frame=self.max_frame)
            h, w = arr.shape
            return rosmsg.RosImage(c.stamp_ns, c.frame_id, h, w, pix, 0, w * arr.itemsize, memoryview(arr.tobytes()))
        if self.enc == "cdr":
            img = _ros_image(data, what)
        elif self.enc == "json":
            img = _json_image(data, what)
        else:
            img = _protobuf_image(self._proto, data, what)
        if check_size:
            check_frame_size(img.width, img.height, self.max_frame, what)
        return img

    def info(self, data: bytes, what: str) -> dict[str, Any]:
        return _camera_info((self.enc, self._proto), data, what)


def _depth_metres(img: rosmsg.RosImage, what: str, depth_scale: float = 1.0) -> np.ndarray:
    scale = DEPTH_ENCODINGS.get(img.encoding)
    if img.encoding not in rosmsg.BYTES_PER_PIXEL:
        raise McapDataError(
            f"{what}: unknown pixel encoding '{img.encoding}'; depth must be 32FC1 (metres), "
            "16UC1 (millimetres) or 64FC1 (metres)"
        )
    arr = rosmsg.image_to_array(img, what=what)  # size checks before trusting pixels
    if scale is None:
        raise McapDataError(
            f"{what}: pixel encoding '{img.encoding}' is not a depth image; expected 32FC1 (metres) or "
            "16UC1 (millimetres); choose the depth topic with `depth_topic`"
        )
    scale *= depth_scale
    if scale == 1.0:
        return arr.astype(np.float32, copy=False)
    return arr.astype(np.float32) * np.float32(scale)


def _valid_median(depth: np.ndarray) -> float:
    """Median of the valid (finite, > 0) depths of a subsample of ~4096 pixels; NaN without any."""
    h, w = depth.shape
    stride = max(1, int(math.sqrt(h * w / 4096)))
    sub = depth[::stride, ::stride]
    v = sub[valid_mask(sub)]
    return float(np.median(v)) if v.size else math.nan


def _label_mask(img: rosmsg.RosImage, what: str) -> np.ndarray:
    if img.encoding not in LABEL_ENCODINGS:
        raise McapDataError(
            f"{what}: label images must be mono8 (0 = background, nonzero = object), got '{img.encoding}'"
        )
    arr = rosmsg.image_to_array(img, what=what)
    return (arr > 0).astype(np.uint8)


# ---------------------------------------------------------------------------- topic choice


def _tokens(topic: str) -> list[str]:
    return [t for t in re.split(r"[/_\-.]+", topic.lower()) if t]


def _namespace(topic: str) -> str:
    return topic.rsplit("/", 1)[0]


def _list(items: list[str], limit: int = 12) -> str:
    if len(items) <= limit:
        return ", ".join(items)
    return ", ".join(items[:limit]) + f", ... ({len(items) - limit} more)"


def _pick_depth(topics: dict[str, _TopicInfo], path: Path, damage: str | None) -> tuple[str, str]:
    images = [t for t in topics.values() if t.kind == "image"]
    cands = [
        t for t in images
        if t.first_encoding in AUTO_DEPTH_ENCODINGS and not (_NOT_DEPTH_TOKENS & set(_tokens(t.topic)))
    ]
    if len(cands) > 1:
        named = [t for t in cands if "depth" in t.topic.lower()]
        if len(named) == 1:
            return named[0].topic, f"only depth-named {named[0].first_encoding} image topic among {len(cands)}"
        raise McapDataError(
            f"{path}: several depth image topics: {_list([t.describe() for t in cands])}; choose one with `depth_topic`"
        )
    if cands:
        t = cands[0]
        return t.topic, f"the only {t.first_encoding} depth image topic"
    where = f" before the damage ({damage})" if damage else ""
    if images:
        raise McapDataError(
            f"{path}: no depth image topic (32FC1 metres or 16UC1 millimetres){where}; image topics: "
            f"{_list([t.describe() for t in images])}; choose one with `depth_topic` if it holds depth"
        )
    if not topics:
        raise McapDataError(f"{path}: the recording holds no messages{where}")
    bad = sorted({t.message_encoding for t in topics.values() if t.message_encoding not in _DECODABLE})
    if bad and all(t.message_encoding not in _DECODABLE for t in topics.values()):
        raise McapDataError(
            f"{path}: message encoding {', '.join(repr(b) for b in bad)} cannot be decoded (supported: "
            f"{', '.join(_DECODABLE)}) and no topic holds depth images; topics: "
            f"{_list(sorted(t.describe() for t in topics.values()))}"
        )
    raise McapDataError(
        f"{path}: no depth images (sensor_msgs/msg/Image or foxglove.RawImage){where}; topics: "
        f"{_list(sorted(t.describe() for t in topics.values()))}"
    )


def _pick_labels(topics: dict[str, _TopicInfo], depth: str) -> str | None:
    cands = [
        t for t in topics.values()
        if t.kind == "image" and t.topic != depth and {"label", "labels"} & set(_tokens(t.topic))
        and (t.first_encoding is None or t.first_encoding in LABEL_ENCODINGS) and t.n_messages != 0
    ]
    if len(cands) > 1:
        cands = [t for t in cands if _namespace(t.topic) == _namespace(depth)]
    return cands[0].topic if len(cands) == 1 else None


def _pick_info(topics: dict[str, _TopicInfo], depth: str) -> str | None:
    cands = [t for t in topics.values() if t.kind == "info" and t.n_messages != 0]
    if len(cands) > 1:
        cands = [t for t in cands if _namespace(t.topic) == _namespace(depth)]
    return cands[0].topic if len(cands) == 1 else None


def _check_topic(
    topics: dict[str, _TopicInfo], topic: str, role: str, path: Path, flag: str, damage: str | None = None
) -> None:
    info = topics.get(topic)
    if info is None:
        images = [t.describe() for t in topics.values() if t.kind == "image"]
        where = f" before the damage ({damage})" if damage else ""
        raise McapDataError(
            f"{path}: no {role} topic '{topic}'{where}; image topics: {_list(images) if images else 'none'}; "
            f"check {flag}"
        )
    if info.kind != "image":
        raise McapDataError(
            f"{path}: {role} topic {topic} carries '{info.schema_name}', not sensor_msgs/msg/Image or "
            "foxglove.RawImage"
        )
    if info.message_encoding not in _DECODABLE:
        raise McapDataError(
            f"{path}: {topic}: message encoding '{info.message_encoding}' cannot be decoded; supported: "
            + ", ".join(_DECODABLE)
        )


# ---------------------------------------------------------------------------- pairing


class _Pairer:
    """Attach labels (and the simulator's extras) to depth frames by timestamp, in file order.

    The one pairing rule: an attachment belongs to a depth frame when their header stamps differ
    by at most the tolerance; when either header stamp is 0 (no stamp: the scene JSON, some
    recorders), their log times are compared instead, so a stamp is never compared with a log
    time. At most ``window`` frames and ``window`` attachments of each kind are held.
    """

    def __init__(self, kinds: tuple[str, ...], tolerance_ns: int, window: int) -> None:
        self.kinds = kinds  # Frame attributes to fill: "label", "clean", "scene"
        self.tol = tolerance_ns
        self.window = window
        self.frames: deque[Frame] = deque()
        self.pending: dict[str, deque[tuple[int, int, Any]]] = {k: deque() for k in kinds}
        self.last: dict[str, tuple[int, int] | None] = {k: None for k in kinds}

    @staticmethod
    def _times(fr: Frame) -> tuple[int, int]:
        return fr.extra.get("header_stamp_ns", 0), fr.stamp_ns

    def _delta(self, fr: Frame, stamp: int, log: int) -> int:
        """Attachment time minus frame time, on the clock both have."""
        fs, fl = self._times(fr)
        return stamp - fs if stamp > 0 and fs > 0 else log - fl

    def add_depth(self, fr: Frame) -> None:
        for kind in self.kinds:
            q = self.pending[kind]
            for i, (stamp, log, value) in enumerate(q):
                if abs(self._delta(fr, stamp, log)) <= self.tol:
                    setattr(fr, kind, value)
                    del q[i]
                    break
        self.frames.append(fr)

    def add(self, kind: str, stamp: int, log: int, value: Any) -> None:
        self.last[kind] = (stamp, log)
        for fr in self.frames:
            if getattr(fr, kind) is None and abs(self._delta(fr, stamp, log)) <= self.tol:
                setattr(fr, kind, value)
                return
        q = self.pending[kind]
        q.append((stamp, log, value))
        while len(q) > self.window:
            q.popleft()

    def _complete(self, fr: Frame) -> bool:
        """Every kind attached, or the stream of that kind has moved past the frame."""
        for kind in self.kinds:
            if getattr(fr, kind) is not None:
                continue
            last = self.last[kind]
            if last is None or self._delta(fr, *last) <= self.tol:
                return False
        return True

    def ready(self) -> Iterator[Frame]:
        while self.frames:
            head = self.frames[0]
            if len(self.frames) > self.window or self._complete(head):
                yield self.frames.popleft()
            else:
                return

    def flush(self) -> Iterator[Frame]:
        while self.frames:
            yield self.frames.popleft()


# ---------------------------------------------------------------------------- the stream


class DepthStream:
    """Depth frames of one recording, re-iterable, in file order.

    Attributes set at open: ``depth_topic`` (and ``depth_reason``: why it was chosen),
    ``labels_topic`` (None without labels), ``info_topic``, ``camera_info`` (latest CameraInfo
    fields seen, or None), ``frame_count`` (from the summary, None when unknown), ``profile``.
    ``message_hook`` (set by a writer) sees every message of the file in order during iteration.
    After an iteration: ``frames_read`` and ``damage`` (None, or the message of the error raised).
    ``max_frame``, ``depth_scale`` and ``on_warning``: see `open_depth_stream`.
    """

    def __init__(
        self,
        path: Path,
        size: int,
        topics: dict[str, _TopicInfo],
        depth_topic: str,
        depth_reason: str,
        labels_topic: str | None,
        info_topic: str | None,
        camera_info: dict[str, Any] | None,
        frame_count: int | None,
        profile: str,
        tolerance_ns: int,
        window: int,
        extra_topics: dict[str, str] | None = None,
        max_frame: tuple[int, int] = DEFAULT_MAX_FRAME,
        depth_scale: float = 1.0,
        on_warning: Callable[[str], None] | None = None,
    ) -> None:
        self.path = path
        self.max_frame = max_frame
        self.depth_scale = depth_scale
        self.on_warning = on_warning
        self._warned: set[str] = set()
        self.extra_topics = dict(extra_topics or {})  # "clean"/"scene" -> topic (simulated data)
        self.size = size
        self.topics = topics
        self.depth_topic = depth_topic
        self.depth_reason = depth_reason
        self.labels_topic = labels_topic
        self.info_topic = info_topic
        self.camera_info = camera_info
        self.frame_count = frame_count
        self.profile = profile
        self.tolerance_ns = tolerance_ns
        self.window = window
        self.message_hook: MessageHook | None = None
        self.frames_read = 0
        self.damage: str | None = None
        # schemas/channels from an intact summary, for files that define channels only there
        self._summary_records: tuple[dict[int, Schema], dict[int, Channel]] = ({}, {})
        # ROS bags (`edge.io.bags.BagSource`): the same records, from rosbags instead of the MCAP walk
        self._source = None
        self._chunk_limit = MAX_CHUNK_BYTES

    @property
    def depth_encoding(self) -> str | None:
        return self.topics[self.depth_topic].first_encoding

    def _warn(self, key: str, message: str) -> None:
        """One line per kind of warning and stream (the CLIs print it; else the `logging` warning)."""
        if key in self._warned:
            return
        self._warned.add(key)
        if self.on_warning is not None:
            self.on_warning(message)
        else:
            _log.warning("warning: %s", message)

    def _check_units(self, depth: np.ndarray, encoding: str, what: str) -> None:
        if "mm" in self._warned or encoding not in ("32FC1", "64FC1"):
            return
        med = _valid_median(depth)
        if med > MM_MEDIAN_M:
            self._warn(
                "mm", f"{what}: {encoding} depth has a median of {med:g} m over its valid pixels, beyond any "
                f"time-of-flight range: it looks like millimetres; scale it to metres with a depth scale of "
                f"{0.001 * self.depth_scale:g} (`depth_scale`)"
            )

    def __repr__(self) -> str:
        return f"DepthStream({str(self.path)!r}, depth_topic={self.depth_topic!r}, labels_topic={self.labels_topic!r})"

    def __iter__(self) -> Iterator[Frame]:
        self.frames_read = 0
        self.damage = None
        kinds = (("label",) if self.labels_topic is not None else ()) + tuple(self.extra_topics)
        pairer = _Pairer(kinds, self.tolerance_ns, self.window)
        extra_kind = {t: k for k, t in self.extra_topics.items()}
        decoders: dict[int, _ChannelDecoder] = {}
        wanted = {self.depth_topic, self.labels_topic, self.info_topic, *extra_kind} - {None}
        hook = self.message_hook
        n_depth = 0
        name = self.path.name
        try:
            try:
                schemas, channels = (dict(d) for d in self._summary_records)
                records = (
                    self._source.messages() if self._source is not None
                    else _walk(self.path, self.size, schemas, channels, chunk_limit=self._chunk_limit)
                )
                for schema, channel, msg in records:
                    if hook is not None:
                        hook(schema, channel, msg)
                    topic = channel.topic
                    if topic not in wanted:
                        continue
                    if extra_kind.get(topic) == "scene":
                        pairer.add("scene", 0, msg.log_time, decode_scene(channel.message_encoding, msg.data))
                        continue
                    dec = decoders.get(channel.id)
                    if dec is None:
                        dec = decoders[channel.id] = _ChannelDecoder(schema, channel, self.max_frame)
                    if topic == self.depth_topic:
                        what = f"{name} {topic} message {n_depth} (log time {msg.log_time} ns)"
                        img = dec.image(msg.data, what)
                        depth = _depth_metres(img, what, self.depth_scale)
                        self._check_units(depth, img.encoding, f"{name} {topic}")
                        pairer.add_depth(
                            Frame(
                                depth=depth, stamp_ns=msg.log_time, info=self.camera_info, topic=topic,
                                extra={
                                    "index": n_depth, "header_stamp_ns": img.stamp_ns,
                                    "frame_id": img.frame_id, "encoding": img.encoding,
                                    "publish_time": msg.publish_time, "sequence": msg.sequence,
                                },
                            )
                        )
                        n_depth += 1
                    elif topic == self.labels_topic:
                        what = f"{name} {topic} message at log time {msg.log_time} ns"
                        img = dec.image(msg.data, what)
                        pairer.add("label", img.stamp_ns, msg.log_time, _label_mask(img, what))
                    elif topic in extra_kind:
                        what = f"{name} {topic} message at log time {msg.log_time} ns"
                        img = dec.image(msg.data, what)
                        pairer.add("clean", img.stamp_ns, msg.log_time, _depth_metres(img, what, self.depth_scale))
                    else:
                        try:
                            self.camera_info = dec.info(msg.data, f"{name} {topic}")
                        except McapDataError as exc:  # optional data: keep the last good calibration
                            self._warn("info", f"{exc}; camera info messages like it are ignored")
                    for fr in pairer.ready():
                        self.frames_read += 1
                        yield fr
            except _Damage as d:
                raise McapDataError(
                    f"{self.path}: damaged at byte {d.offset} of {self.size}: {d.what}; "
                    f"{n_depth} depth frames were read before it"
                ) from None
        except McapDataError as exc:
            self.damage = str(exc)
            for fr in pairer.flush():
                self.frames_read += 1
                yield fr
            raise
        for fr in pairer.flush():
            self.frames_read += 1
            yield fr
        if n_depth == 0:
            raise McapDataError(f"{self.path}: topic {self.depth_topic} has no messages; nothing to replay")


def _check_file(path: Path) -> int:
    if not path.exists():
        raise McapDataError(f"{path}: no such file")
    if path.is_dir():
        inside = sorted(f.name for f in path.glob("*.mcap") if not f.name.startswith("."))
        hint = f" (it holds {_list(inside, 3)})" if inside else ""
        raise McapDataError(
            f"{path}: is a directory without metadata.yaml, so not a ROS 2 bag; pass one .mcap, .bag or .db3 "
            f"recording{hint}"
        )
    size = path.stat().st_size
    if size == 0:
        raise McapDataError(f"{path}: empty file (0 bytes), not an MCAP recording")
    try:
        with open(path, "rb") as fh:
            magic = fh.read(MAGIC_SIZE)
    except PermissionError:
        raise McapDataError(f"{path}: permission denied") from None
    if magic != MCAP_MAGIC:
        if len(magic) < MAGIC_SIZE and MCAP_MAGIC.startswith(magic):
            raise McapDataError(f"{path}: only {size} bytes: truncated inside the MCAP magic")
        raise McapDataError(
            f"{path}: not an MCAP file (starts with {magic[:8]!r}); recordings must be .mcap, a ROS 1 .bag, "
            "a ROS 2 .db3 or a ROS 2 bag directory"
        )
    return size


def _read_summary(path: Path):
    """(channels, schemas, message counts per channel or None); None when the summary is unusable."""
    from mcap.reader import SeekingReader

    try:
        with open(path, "rb") as fh:
            summary = SeekingReader(fh, record_size_limit=os.path.getsize(path)).get_summary()
    except Exception:  # missing/corrupt footer: the walk finds the channels instead
        return None
    if summary is None:
        return None
    counts = summary.statistics.channel_message_counts if summary.statistics else None
    return summary.channels, summary.schemas, counts


def _peek_image(
    schema: Schema | None, channel: Channel, msg: Message, info: _TopicInfo, max_frame: tuple[int, int]
) -> None:
    try:
        img = _ChannelDecoder(schema, channel, max_frame).image(msg.data, channel.topic, check_size=False)
        info.first_encoding = img.encoding
        info.first_size = (img.height, img.width)
    except (McapDataError, struct.error) as exc:
        info.peek_error = str(exc)


def open_depth_stream(
    path: str | Path,
    topic: str | None = None,
    labels_topic: str | None = None,
    *,
    tolerance_ns: int = DEFAULT_TOLERANCE_NS,
    window: int = DEFAULT_WINDOW,
    peek_bytes: int = PEEK_BYTES,
    extras: tuple[str, ...] = (),
    max_frame: tuple[int, int] = DEFAULT_MAX_FRAME,
    depth_scale: float = 1.0,
    on_warning: Callable[[str], None] | None = None,
) -> DepthStream:
    """Open ``path`` and decide which topics hold depth, labels and camera info.

    ``topic`` / ``labels_topic`` override the automatic choice (``labels_topic=""`` disables
    labels). ``extras`` (``"clean"``, ``"scene"``) also pairs the simulator's noise-free depth
    and scene JSON (`edge.io.frames` layout) with each frame when the file has them.

    Hostile input is bounded: ``max_frame`` (width, height) refuses larger frames from their
    header, before pixels are allocated or handed to a model, and chunks decompress only up to
    their declared size (at most `MAX_CHUNK_BYTES`, or twice the largest 64FC1 frame allowed).
    FIFOs, devices and sockets are refused (`edge.io.paths.check_input_file`): the reader opens
    a recording several times, and a pipe with no writer would block forever.

    ``depth_scale`` multiplies the decoded metres (after 16UC1's millimetre conversion): 0.001
    reads millimetres stored as 32FC1. A 32FC1/64FC1 frame whose valid median is beyond
    `MM_MEDIAN_M` (10 m, no ToF camera reaches it) gets one warning per stream saying so,
    through ``on_warning`` (default: a `logging` warning, which Python prints on stderr).

    Raises `McapDataError` (one line) when the file is not a readable recording or holds
    no usable depth topic; damage *after* the first depth frame is reported during iteration.
    `ConfigError` for a bad ``max_frame`` or ``depth_scale``; `DataError` for a special file.
    """
    p = Path(path)
    if p.exists():  # (a missing file is _check_file's one line)
        check_input_file(p, "recording", allow_dir=True)
    max_frame = _check_max_frame(max_frame)
    if isinstance(depth_scale, bool) or not isinstance(depth_scale, (int, float)) or not (
        math.isfinite(depth_scale) and depth_scale > 0
    ):
        raise ConfigError(f"`depth_scale` must be a positive finite number (0.001 reads millimetres), got {depth_scale}")
    chunk_limit = max(MAX_CHUNK_BYTES, 2 * 8 * max_frame[0] * max_frame[1])
    if p.is_dir() and is_bag(p):
        _check_bag_chunks(p, chunk_limit)
    elif p.is_file() and bag_kind(p) == "ros1":
        _check_ros1_chunks(p, chunk_limit)
    bag = open_bag(p)
    if bag is None:
        size = _check_file(p)
        summ = _read_summary(p)
    else:
        size, summ = bag.size, bag.summary()
    schemas: dict[int, Schema] = {}
    channels: dict[int, Channel] = {}
    counts: dict[int, int] | None = None
    if summ is not None:
        channels, schemas, counts = dict(summ[0]), dict(summ[1]), summ[2]
    topics: dict[str, _TopicInfo] = {}

    def note(ch: Channel) -> _TopicInfo:
        t = topics.get(ch.topic)
        if t is None:
            s = schemas.get(ch.schema_id) if ch.schema_id else None
            t = topics[ch.topic] = _TopicInfo(
                ch.topic, s.name if s else "", s.encoding if s else "", ch.message_encoding
            )
        if ch.id not in t.channel_ids:
            t.channel_ids.append(ch.id)
        return t

    def has_messages(t: _TopicInfo) -> bool:
        return counts is None or any(counts.get(c, 0) > 0 for c in t.channel_ids)

    for ch in channels.values():
        note(ch)
    if counts is not None:
        for t in topics.values():
            t.n_messages = sum(counts.get(c, 0) for c in t.channel_ids)
    headers: list[Header] = []
    damage: str | None = None
    infos: dict[str, dict[str, Any]] = {}
    pos = [0]
    try:
        records = bag.messages(pos) if bag is not None else _walk(p, size, schemas, channels, headers, pos, chunk_limit)
        for schema, channel, msg in records:
            t = note(channel)
            if t.kind == "image" and t.first_encoding is None and t.peek_error is None:
                _peek_image(schema, channel, msg, t, max_frame)
            elif t.kind == "info" and channel.topic not in infos:
                try:
                    infos[channel.topic] = _ChannelDecoder(schema, channel, max_frame).info(msg.data, channel.topic)
                except (McapDataError, struct.error, IndexError):
                    pass
            pending = [x for x in topics.values() if x.kind == "image" and x.first_encoding is None
                       and x.peek_error is None and has_messages(x)]
            if summ is not None and not pending:
                break
            if pos[0] > peek_bytes:
                break
    except _Damage as d:
        damage = f"byte {d.offset}: {d.what}"
    if topic:
        _check_topic(topics, topic, "depth", p, "`depth_topic`", damage)
        depth, reason = topic, "chosen explicitly"
    else:
        depth, reason = _pick_depth(topics, p, damage)
    if labels_topic:
        _check_topic(topics, labels_topic, "labels", p, "`labels_topic`", damage)
        if labels_topic == depth:
            raise McapDataError(f"{p}: `labels_topic` {labels_topic} is the depth topic; choose the label topic")
        labels: str | None = labels_topic
    elif labels_topic == "":
        labels = None
    else:
        labels = _pick_labels(topics, depth)
    info_topic = _pick_info(topics, depth)
    camera_info = infos.get(info_topic) if info_topic else None
    frame_count = None
    if counts is not None:
        frame_count = sum(counts.get(c, 0) for c in topics[depth].channel_ids)
        if frame_count == 0:
            raise McapDataError(f"{p}: topic {depth} has no messages; nothing to replay")
    profile = headers[0].profile if headers else ("ros2" if bag is not None else "")
    unknown = set(extras) - set(EXTRA_TOPICS)
    if unknown:
        raise ConfigError(f"unknown extras {sorted(unknown)}; choose from {sorted(EXTRA_TOPICS)}")
    extra_topics = {k: EXTRA_TOPICS[k] for k in extras if EXTRA_TOPICS[k] in topics and EXTRA_TOPICS[k] != depth}
    stream = DepthStream(
        p, size, topics, depth, reason, labels, info_topic, camera_info, frame_count, profile,
        int(tolerance_ns), int(window), extra_topics, max_frame, float(depth_scale), on_warning,
    )
    stream._chunk_limit = chunk_limit
    if summ is not None:
        stream._summary_records = (dict(summ[1]), dict(summ[0]))
    stream._source = bag
    return stream


# ---------------------------------------------------------------------------- files and directories


def list_mcap_files(path: str | Path) -> list[Path]:
    """One recording, or the recordings of a directory (sorted; hidden temp files skipped).

    Recordings: .mcap files, ROS 1 .bag, ROS 2 .db3 files and ROS 2 bag directories (metadata.yaml),
    the last three read through `edge.io.bags`.
    """
    p = Path(path)
    if not p.exists():
        raise DataError(f"{p}: no such file or directory")
    check_input_file(p, "data", allow_dir=True)
    if p.is_dir() and is_bag(p):
        return [p]  # a ROS 2 bag directory is one recording
    if p.is_dir():
        files = sorted(
            f for f in p.iterdir() if not f.name.startswith(".") and (f.suffix == ".mcap" or is_bag(f))
        )
        if not files:
            raise DataError(
                f"{p}: directory holds no recordings (.mcap, .bag, .db3 or ROS 2 bag directories); pass a "
                f"recording, or simulate labelled frames with depthseg-sim --out {p}"
            )
        return files
    return [p]


def open_frames(
    path: str | Path,
    depth_topic: str | None = None,
    labels_topic: str | None = None,
    *,
    require_labels: bool = False,
    extras: tuple[str, ...] = (),
    tolerance_ns: int = DEFAULT_TOLERANCE_NS,
    max_frame: tuple[int, int] = DEFAULT_MAX_FRAME,
    depth_scale: float = 1.0,
    on_warning: Callable[[str], None] | None = None,
) -> tuple[Iterator[Frame], int | None]:
    """Frames of one recording or of every recording in a directory, and their count when known.

    Every file is opened (topics detected, labels checked) before the first frame is delivered,
    so a missing label topic fails at once instead of after minutes of work. Training, evaluation,
    tuning and the tools all read through here, so a recording one of them accepts, all accept.

    Args:
        path: a recording (`list_mcap_files`) or a directory of them.
        depth_topic: the depth Image topic (None: detected per file).
        labels_topic: the label Image topic (None: detected; ``""``: no labels).
        require_labels: raise when a file has no label topic or no label message.
        extras: also pair the simulator's ``"clean"`` depth and/or ``"scene"`` JSON.
        tolerance_ns: largest stamp difference of a label and its depth frame.
        max_frame, depth_scale, on_warning: as `open_depth_stream` (a warning is given once for
            all files, not once per file).

    Returns:
        (a generator of `Frame` over all files in order, the number of depth frames or None).

    Raises:
        DataError: no such path, no recording, or (with ``require_labels``) no labels.
        McapDataError: a file is not a readable recording.
    """
    streams = []
    total: int | None = 0
    warned: set[str] = set()
    for f in list_mcap_files(path):
        st = open_depth_stream(f, topic=depth_topic, labels_topic=labels_topic, tolerance_ns=tolerance_ns,
                               extras=extras, max_frame=max_frame, depth_scale=depth_scale, on_warning=on_warning)
        st._warned = warned  # one warning of each kind for the whole directory
        if require_labels:
            lt = st.topics.get(st.labels_topic) if st.labels_topic else None
            if lt is None or lt.n_messages == 0:
                present = sorted(t.topic for t in st.topics.values() if t.n_messages != 0)
                raise DataError(
                    f"{f}: no labels found for depth topic {st.depth_topic} (looked for a mono8 Image topic named "
                    f"'label(s)'); topics present: {', '.join(present) or 'none'}; name it with `labels_topic`"
                )
        streams.append(st)
        total = None if total is None or st.frame_count is None else total + st.frame_count

    def chain() -> Iterator[Frame]:
        for st in streams:
            yield from st

    return chain(), total


def iter_frames(
    path: str | Path,
    depth_topic: str | None = None,
    labels_topic: str | None = None,
    with_clean: bool = False,
    **kw: Any,
) -> Iterator[Frame]:
    """Stream frames (labels where present; the simulator's scene, and its clean depth if asked).

    `open_frames` without the count: the same reader, the same topic detection and pairing;
    ``kw``: its ``max_frame``, ``depth_scale``, ``on_warning``.
    """
    frames, _ = open_frames(path, depth_topic, labels_topic, extras=("scene", "clean") if with_clean else ("scene",),
                            **kw)
    yield from frames

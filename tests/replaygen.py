"""Small MCAP recordings in every layout the replay reader supports, generated per test.

Writers used on purpose: ``mcap.writer`` + ``edge.rosmsg`` for ROS 2 (what a rosbag2 file holds),
``mcap_protobuf.writer`` with a ``foxglove.RawImage`` class built from a hand-made
FileDescriptorSet (what the Foxglove SDK writes), and JSON with base64 data (Foxglove's JSON
encoding). Depth scenes are deterministic functions of the frame index.
"""

from __future__ import annotations

import base64
import json
from dataclasses import dataclass
from pathlib import Path
from types import SimpleNamespace

import numpy as np
from mcap.writer import CompressionType, Writer

from edge import rosmsg
from edge.preprocess import valid_mask

SHARED = Path(__file__).resolve().parents[1].parent / "shared"
T0 = 1_700_000_000_000_000_000
PERIOD = 50_000_000  # 20 fps
KINDS = ("ros32_zero", "ros32_nan", "ros16", "fox_proto", "fox_json")


def scene(i: int, h: int = 24, w: int = 32, box: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """(depth metres with invalid = 0, label) of frame ``i``: a table with a box (none when not
    ``box``: every other pixel as with it) and dead corners."""
    rng = np.random.default_rng([7, i])
    depth = np.full((h, w), 0.30, dtype=np.float32) + rng.normal(0, 0.002, (h, w)).astype(np.float32)
    label = np.zeros((h, w), dtype=np.uint8)
    r0, c0 = 2 + i % max(1, h - 10), 3 + (2 * i) % max(1, w - 12)
    if box:
        depth[r0 : r0 + 6, c0 : c0 + 8] -= 0.05
        label[r0 : r0 + 6, c0 : c0 + 8] = 1
    depth[:2, :2] = 0.0
    depth[-1, -3:] = 0.0
    dead = rng.random((h, w)) < 0.02
    depth[dead] = 0.0
    return depth, label


def _invalid_as(depth: np.ndarray, invalid: str) -> np.ndarray:
    out = depth.copy()
    if invalid == "nan":
        out[depth == 0] = np.nan
    return out


# ------------------------------------------------------------------ ROS 2


@dataclass
class Rec:
    path: Path
    depth: list[np.ndarray]  # what the reader must return (metres, float32)
    label: list[np.ndarray]
    topic: str
    labels_topic: str | None


def write_ros2(
    path: Path,
    n: int = 6,
    encoding: str = "32FC1",
    invalid: str = "zero",
    labels: bool = True,
    info: bool = True,
    size: tuple[int, int] = (24, 32),
    topic: str = "/pico_flexx/image_depth",
    labels_topic: str = "/pico_flexx/labels",
    chunk_size: int = 4096,
    compression: CompressionType = CompressionType.ZSTD,
    message_encoding: str = "cdr",
    extra: dict[str, tuple[str, np.ndarray]] | None = None,
    corrupt_frame: int | None = None,
) -> Rec:
    """A rosbag2-like file: Image (+ labels, CameraInfo, extra Image topics) per frame."""
    h, w = size
    with open(path, "wb") as fh:
        wr = Writer(fh, chunk_size=chunk_size, compression=compression)
        wr.start(profile="ros2", library="test")
        img = wr.register_schema(rosmsg.IMAGE_TYPE, "ros2msg", rosmsg.IMAGE_MSGDEF.encode())
        inf = wr.register_schema(rosmsg.CAMERA_INFO_TYPE, "ros2msg", rosmsg.CAMERA_INFO_MSGDEF.encode())
        ch_d = wr.register_channel(topic, message_encoding, img)
        ch_l = wr.register_channel(labels_topic, "cdr", img) if labels else None
        ch_i = wr.register_channel("/pico_flexx/camera_info", "cdr", inf) if info else None
        ch_x = {t: wr.register_channel(t, "cdr", img) for t in (extra or {})}
        depths, labs = [], []
        for i in range(n):
            d, lab = scene(i, h, w)
            t = T0 + i * PERIOD
            if info:
                wr.add_message(ch_i, t, rosmsg.encode_camera_info(t, "cam", w, h, 200.0, 201.0, w / 2, h / 2), t)
            if encoding == "16UC1":
                arr = np.round(d * 1000).astype(np.uint16)
                expect = arr.astype(np.float32) * np.float32(0.001)
            elif encoding == "64FC1":
                arr = _invalid_as(d, invalid).astype(np.float64)
                expect = arr.astype(np.float32)
            else:
                arr = _invalid_as(d, invalid)
                expect = arr
            data = rosmsg.encode_image(t, "cam", arr, encoding)
            if corrupt_frame == i:  # height x step no longer matches the data
                data = _claim_height(rosmsg.encode_image(t, "cam", arr[:-1], encoding), h)
            wr.add_message(ch_d, t, data, t)
            for tx, (enc, a) in (extra or {}).items():
                wr.add_message(ch_x[tx], t, rosmsg.encode_image(t, "cam", a, enc), t)
            if labels:
                wr.add_message(ch_l, t, rosmsg.encode_image(t, "cam", lab, "mono8"), t)
            depths.append(expect)
            labs.append(lab)
        wr.finish()
    return Rec(path, depths, labs, topic, labels_topic if labels else None)


def _claim_height(data: bytes, h: int) -> bytes:
    """Rewrite the height field of a CDR Image (after header stamp + frame_id 'cam')."""
    # layout: encap(4) sec(4) nsec(4) len(4) 'cam\\0'(4) height(4)
    return data[:20] + int(h).to_bytes(4, "little") + data[24:]


# ------------------------------------------------------------------ foxglove


def rawimage_class():
    """A foxglove.RawImage protobuf class from a hand-built FileDescriptorSet (foxglove schema)."""
    from google.protobuf import descriptor_pb2, descriptor_pool, timestamp_pb2
    from google.protobuf.message_factory import GetMessageClass

    pool = descriptor_pool.DescriptorPool()
    ts = descriptor_pb2.FileDescriptorProto()
    timestamp_pb2.DESCRIPTOR.CopyToProto(ts)
    pool.Add(ts)
    f = descriptor_pb2.FileDescriptorProto(
        name="foxglove/RawImage.proto", package="foxglove", syntax="proto3",
        dependency=["google/protobuf/timestamp.proto"],
    )
    m = f.message_type.add(name="RawImage")
    T = descriptor_pb2.FieldDescriptorProto
    for name, num, typ, tname in (
        ("timestamp", 1, T.TYPE_MESSAGE, ".google.protobuf.Timestamp"),
        ("frame_id", 7, T.TYPE_STRING, None),
        ("width", 2, T.TYPE_FIXED32, None),
        ("height", 3, T.TYPE_FIXED32, None),
        ("encoding", 4, T.TYPE_STRING, None),
        ("step", 5, T.TYPE_FIXED32, None),
        ("data", 6, T.TYPE_BYTES, None),
    ):
        fd = m.field.add(name=name, number=num, type=typ, label=T.LABEL_OPTIONAL)
        if tname:
            fd.type_name = tname
    pool.Add(f)
    return GetMessageClass(pool.FindMessageTypeByName("foxglove.RawImage"))


RAW_JSON_SCHEMA = json.dumps(
    {
        "title": "foxglove.RawImage",
        "type": "object",
        "properties": {
            "timestamp": {"type": "object", "properties": {"sec": {"type": "integer"}, "nsec": {"type": "integer"}}},
            "frame_id": {"type": "string"},
            "width": {"type": "integer"},
            "height": {"type": "integer"},
            "encoding": {"type": "string"},
            "step": {"type": "integer"},
            "data": {"type": "string", "contentEncoding": "base64"},
        },
    }
).encode()


def _fox_fields(t: int, arr: np.ndarray, encoding: str) -> dict:
    a = np.ascontiguousarray(arr)
    return dict(
        sec=t // 1_000_000_000, nsec=t % 1_000_000_000, frame_id="cam", width=a.shape[1], height=a.shape[0],
        encoding=encoding, step=a.strides[0], data=a.astype(a.dtype.newbyteorder("<")).tobytes(),
    )


def write_foxglove(
    path: Path,
    n: int = 6,
    fmt: str = "protobuf",
    encoding: str = "32FC1",
    labels: bool = True,
    size: tuple[int, int] = (24, 32),
    topic: str = "/camera/depth",
    labels_topic: str = "/camera/labels",
    chunk_size: int = 4096,
    bad_step_frame: int | None = None,
) -> Rec:
    """A Foxglove-SDK-like recording of RawImage depth (+ mono8 labels) in protobuf or JSON."""
    h, w = size
    depths, labs = [], []
    frames = []
    for i in range(n):
        d, lab = scene(i, h, w)
        t = T0 + i * PERIOD
        if encoding == "16UC1":
            arr = np.round(d * 1000).astype(np.uint16)
            depths.append(arr.astype(np.float32) * np.float32(0.001))
        else:
            arr = d
            depths.append(d)
        labs.append(lab)
        frames.append((t, _fox_fields(t, arr, encoding), _fox_fields(t, lab, "mono8")))
        if bad_step_frame == i:
            frames[-1][1]["step"] += 4
    if fmt == "protobuf":
        from mcap_protobuf.writer import Writer as PbWriter

        Raw = rawimage_class()

        def pb(f: dict):
            m = Raw(frame_id=f["frame_id"], width=f["width"], height=f["height"], encoding=f["encoding"],
                    step=f["step"], data=f["data"])
            m.timestamp.seconds = f["sec"]
            m.timestamp.nanos = f["nsec"]
            return m

        with open(path, "wb") as fh:
            wr = PbWriter(fh, chunk_size=chunk_size)
            for t, fd, fl in frames:
                wr.write_message(topic, pb(fd), log_time=t, publish_time=t)
                if labels:
                    wr.write_message(labels_topic, pb(fl), log_time=t, publish_time=t)
            wr.finish()
    else:
        with open(path, "wb") as fh:
            wr = Writer(fh, chunk_size=chunk_size)
            wr.start(profile="", library="test")
            sid = wr.register_schema("foxglove.RawImage", "jsonschema", RAW_JSON_SCHEMA)
            ch_d = wr.register_channel(topic, "json", sid)
            ch_l = wr.register_channel(labels_topic, "json", sid)

            def js(f: dict) -> bytes:
                return json.dumps({
                    "timestamp": {"sec": f["sec"], "nsec": f["nsec"]}, "frame_id": f["frame_id"],
                    "width": f["width"], "height": f["height"], "encoding": f["encoding"], "step": f["step"],
                    "data": base64.b64encode(f["data"]).decode(),
                }).encode()

            for t, fd, fl in frames:
                wr.add_message(ch_d, t, js(fd), t)
                if labels:
                    wr.add_message(ch_l, t, js(fl), t)
            wr.finish()
    return Rec(path, depths, labs, topic, labels_topic if labels else None)


def write_kind(kind: str, path: Path, **kw) -> Rec:
    """One of KINDS: the five reader paths the issue names."""
    if kind == "ros32_zero":
        return write_ros2(path, encoding="32FC1", invalid="zero", **kw)
    if kind == "ros32_nan":
        return write_ros2(path, encoding="32FC1", invalid="nan", **kw)
    if kind == "ros16":
        return write_ros2(path, encoding="16UC1", **kw)
    if kind == "fox_proto":
        return write_foxglove(path, fmt="protobuf", **kw)
    if kind == "fox_json":
        return write_foxglove(path, fmt="json", **kw)
    raise ValueError(kind)


# ------------------------------------------------------------------ stand-in segmenter


class FakeSegmenter:
    """Duck-typed `edge.infer.Segmenter` for loop tests: object = nearer than ``cut`` metres.

    ``oracle`` maps frame stamps to labels to predict perfectly; ``invert`` flips the answer.
    """

    def __init__(self, cut: float = 0.275, threshold: float = 0.5, invert: bool = False) -> None:
        self.cut = cut
        self.threshold = threshold
        self.min_object_px = 0  # its masks are the bare threshold rule
        self.invert = invert
        self.calls = 0

    def predict(self, depth: np.ndarray):
        self.calls += 1
        valid = valid_mask(depth)
        d = np.where(valid, depth, self.cut)
        prob = (1.0 / (1.0 + np.exp((d - self.cut) * 400.0))).astype(np.float32)
        if self.invert:
            prob = 1.0 - prob
        mask = np.where(valid, (prob >= self.threshold).astype(np.uint8), np.uint8(255)).astype(np.uint8)
        return SimpleNamespace(prob=prob, mask=mask, valid=valid, timings={"total": 0.0})

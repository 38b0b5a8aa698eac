"""ROS 2 message definitions and a small, fast CDR codec for Image and CameraInfo.

Why our own codec: depth frames are 150 kB byte arrays; encoding them field by field through a
generic dynamic codec costs more than the simulation itself, and decoding must check that the
data length matches height x step *before* trusting it. The output is plain ROS 2 CDR, checked
against ``mcap-ros2-support`` in the tests, so any MCAP tool, ros2 bag and Foxglove read it.
Numpy only (edge path).
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

import numpy as np

from edge.errors import McapDataError

__all__ = [
    "CdrReader",
    "IMAGE_MSGDEF",
    "CAMERA_INFO_MSGDEF",
    "IMAGE_TYPE",
    "CAMERA_INFO_TYPE",
    "RosImage",
    "encode_image",
    "decode_image",
    "image_to_array",
    "encode_camera_info",
    "decode_camera_info",
    "STRING_TYPE",
    "STRING_MSGDEF",
    "encode_string",
    "decode_string",
    "stamp_fits",
]

IMAGE_TYPE = "sensor_msgs/msg/Image"
STRING_TYPE = "std_msgs/msg/String"
STRING_MSGDEF = "string data\n"
CAMERA_INFO_TYPE = "sensor_msgs/msg/CameraInfo"

_HEADER_DEF = """================================================================================
MSG: std_msgs/Header
builtin_interfaces/Time stamp
string frame_id
================================================================================
MSG: builtin_interfaces/Time
int32 sec
uint32 nanosec"""

IMAGE_MSGDEF = (
    """std_msgs/Header header
uint32 height
uint32 width
string encoding
uint8 is_bigendian
uint32 step
uint8[] data
"""
    + _HEADER_DEF
)

CAMERA_INFO_MSGDEF = (
    """std_msgs/Header header
uint32 height
uint32 width
string distortion_model
float64[] d
float64[9] k
float64[9] r
float64[12] p
uint32 binning_x
uint32 binning_y
sensor_msgs/RegionOfInterest roi
"""
    + _HEADER_DEF
    + """
================================================================================
MSG: sensor_msgs/RegionOfInterest
uint32 x_offset
uint32 y_offset
uint32 height
uint32 width
bool do_rectify"""
)

_ENCAP_LE = b"\x00\x01\x00\x00"
_INT32 = 1 << 31


def stamp_fits(stamp_ns: int) -> bool:
    """Whether ``stamp_ns`` can be a std_msgs/Header stamp (int32 seconds; after 2038 it cannot)."""
    return -_INT32 <= int(stamp_ns) // 1_000_000_000 < _INT32
# bytes per pixel of the encodings a depth or label reader understands
BYTES_PER_PIXEL = {"32FC1": 4, "16UC1": 2, "mono16": 2, "mono8": 1, "8UC1": 1, "rgb8": 3, "bgr8": 3, "64FC1": 8}


class _W:
    """Little-endian CDR writer; offsets are relative to the end of the encapsulation header."""

    def __init__(self) -> None:
        self.parts: list[bytes] = [_ENCAP_LE]
        self.n = 0

    def _align(self, k: int) -> None:
        pad = (-self.n) % k
        if pad:
            self.parts.append(b"\x00" * pad)
            self.n += pad

    def raw(self, b: bytes) -> None:
        self.parts.append(b)
        self.n += len(b)

    def u32(self, v: int) -> None:
        self._align(4)
        self.raw(struct.pack("<I", v))

    def i32(self, v: int) -> None:
        self._align(4)
        self.raw(struct.pack("<i", v))

    def u8(self, v: int) -> None:
        self.raw(struct.pack("<B", v))

    def string(self, s: str) -> None:
        b = s.encode() + b"\x00"
        self.u32(len(b))
        self.raw(b)

    def f64s(self, vals, with_len: bool) -> None:
        vals = list(vals)
        if with_len:
            self.u32(len(vals))
        if vals:
            self._align(8)
            self.raw(struct.pack(f"<{len(vals)}d", *vals))

    def header(self, stamp_ns: int, frame_id: str) -> None:
        sec = int(stamp_ns) // 1_000_000_000
        if not stamp_fits(stamp_ns):
            raise McapDataError(
                f"header stamp {stamp_ns} ns ({sec} s) does not fit a ROS 2 header (int32 seconds: "
                "December 1901 to January 2038)"
            )
        self.i32(sec)
        self.u32(int(stamp_ns) % 1_000_000_000)
        self.string(frame_id)

    def bytes(self) -> bytes:
        return b"".join(self.parts)


class CdrReader:
    """Bounds-checked CDR reader over a message buffer: every read raises `McapDataError` on truncation."""

    def __init__(self, buf: bytes | memoryview, what: str) -> None:
        self.buf = memoryview(buf)
        self.what = what
        if len(self.buf) < 4:
            raise McapDataError(f"{what}: message of {len(self.buf)} bytes is too short for CDR")
        self.le = self.buf[1] in (1, 3)
        self.pos = 4

    def _need(self, k: int) -> None:
        if self.pos + k > len(self.buf):
            raise McapDataError(f"{self.what}: message is truncated ({len(self.buf)} bytes)")

    def _align(self, k: int) -> None:
        self.pos += (-(self.pos - 4)) % k

    def _unpack(self, fmt: str, size: int):
        self._align(size)
        self._need(size)
        v = struct.unpack_from(("<" if self.le else ">") + fmt, self.buf, self.pos)[0]
        self.pos += size
        return v

    def u32(self) -> int:
        return self._unpack("I", 4)

    def i32(self) -> int:
        return self._unpack("i", 4)

    def u8(self) -> int:
        self._need(1)
        v = self.buf[self.pos]
        self.pos += 1
        return v

    def string(self) -> str:
        n = self.u32()
        self._need(n)
        s = bytes(self.buf[self.pos : self.pos + n]).rstrip(b"\x00").decode(errors="replace")
        self.pos += n
        return s

    def header(self) -> tuple[int, str]:
        """std_msgs/Header: (stamp in ns, frame_id)."""
        sec = self.i32()
        nsec = self.u32()
        return sec * 1_000_000_000 + nsec, self.string()

    def blob(self) -> memoryview:
        """A length-prefixed byte sequence (uint8[]), without copying it."""
        n = self.u32()
        self._need(n)
        data = self.buf[self.pos : self.pos + n]
        self.pos += n
        return data

    def f64s(self, n: int | None) -> list[float]:
        if n is None:
            n = self.u32()
        if n == 0:
            return []
        self._align(8)
        self._need(8 * n)
        vals = struct.unpack_from(("<" if self.le else ">") + f"{n}d", self.buf, self.pos)
        self.pos += 8 * n
        return list(vals)


@dataclass
class RosImage:
    stamp_ns: int
    frame_id: str
    height: int
    width: int
    encoding: str
    is_bigendian: int
    step: int
    data: memoryview


def encode_image(stamp_ns: int, frame_id: str, array: np.ndarray, encoding: str) -> bytes:
    """CDR bytes of a sensor_msgs/msg/Image holding ``array`` (H x W [x C]) as ``encoding``."""
    a = np.ascontiguousarray(array)
    h, w = a.shape[:2]
    step = a.strides[0]
    wr = _W()
    wr.header(stamp_ns, frame_id)
    wr.u32(h)
    wr.u32(w)
    wr.string(encoding)
    wr.u8(0 if a.dtype.byteorder in ("<", "=", "|") else 1)
    wr.u32(step)
    data = a.tobytes()
    wr.u32(len(data))
    wr.raw(data)
    return wr.bytes()


def decode_image(buf: bytes | memoryview, what: str = "Image") -> RosImage:
    """Parse a CDR sensor_msgs/msg/Image without copying its pixel data."""
    r = CdrReader(buf, what)
    stamp_ns, frame_id = r.header()
    h = r.u32()
    w = r.u32()
    enc = r.string()
    big = r.u8()
    step = r.u32()
    return RosImage(stamp_ns, frame_id, h, w, enc, big, step, r.blob())


def image_to_array(img: RosImage, what: str = "Image") -> np.ndarray:
    """The pixels as an H x W (x C) array, after checking size against height x step."""
    bpp = BYTES_PER_PIXEL.get(img.encoding)
    if bpp is None:
        raise McapDataError(
            f"{what}: unsupported pixel encoding '{img.encoding}'; "
            f"supported: {', '.join(sorted(BYTES_PER_PIXEL))}"
        )
    if img.height == 0 or img.width == 0:
        raise McapDataError(f"{what}: empty image ({img.height} x {img.width})")
    if img.step < img.width * bpp:
        raise McapDataError(
            f"{what}: step {img.step} is smaller than width {img.width} x {bpp} bytes ({img.encoding})"
        )
    if len(img.data) != img.height * img.step:
        raise McapDataError(
            f"{what}: data has {len(img.data)} bytes but height x step = {img.height} x {img.step} "
            f"= {img.height * img.step}; the message is malformed"
        )
    base = {"32FC1": "f4", "64FC1": "f8", "16UC1": "u2", "mono16": "u2"}.get(img.encoding, "u1")
    dt = np.dtype(base).newbyteorder(">" if img.is_bigendian else "<")
    channels = 3 if img.encoding in ("rgb8", "bgr8") else 1
    rows = np.frombuffer(img.data, dtype=np.uint8).reshape(img.height, img.step)
    rows = rows[:, : img.width * bpp]
    arr = np.ascontiguousarray(rows).view(dt).reshape(img.height, img.width, channels)
    if channels == 1:
        arr = arr[:, :, 0]
    return arr.astype(dt.newbyteorder("="), copy=False)


def encode_camera_info(
    stamp_ns: int,
    frame_id: str,
    width: int,
    height: int,
    fx: float,
    fy: float,
    cx: float,
    cy: float,
    distortion: tuple[float, ...] = (),
) -> bytes:
    wr = _W()
    wr.header(stamp_ns, frame_id)
    wr.u32(height)
    wr.u32(width)
    wr.string("plumb_bob")
    d = list(distortion) + [0.0] * max(0, 5 - len(distortion))
    wr.f64s(d, with_len=True)
    wr.f64s([fx, 0, cx, 0, fy, cy, 0, 0, 1], with_len=False)
    wr.f64s([1, 0, 0, 0, 1, 0, 0, 0, 1], with_len=False)
    wr.f64s([fx, 0, cx, 0, 0, fy, cy, 0, 0, 0, 1, 0], with_len=False)
    wr.u32(0)
    wr.u32(0)
    for _ in range(4):
        wr.u32(0)
    wr.u8(0)
    return wr.bytes()


def encode_string(text: str) -> bytes:
    """CDR bytes of a std_msgs/msg/String (how JSON travels in a ROS 2 file)."""
    wr = _W()
    wr.string(text)
    return wr.bytes()


def decode_string(buf: bytes | memoryview, what: str = "String") -> str:
    return CdrReader(buf, what).string()


def decode_camera_info(buf: bytes | memoryview, what: str = "CameraInfo") -> dict:
    """The fields a depth user needs: size, K (fx, fy, cx, cy) and distortion."""
    r = CdrReader(buf, what)
    _stamp, frame_id = r.header()
    h = r.u32()
    w = r.u32()
    model = r.string()
    d = r.f64s(None)
    k = r.f64s(9)
    return {
        "frame_id": frame_id,
        "height": h,
        "width": w,
        "distortion_model": model,
        "d": d,
        "fx": k[0],
        "fy": k[4],
        "cx": k[2],
        "cy": k[5],
    }

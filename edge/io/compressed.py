"""``sensor_msgs/CompressedImage`` depth: the ``compressedDepth`` transport (and plain 16-bit PNG).

What ``compressed_depth_image_transport`` publishes (ROS 1 and ROS 2, format string such as
``"16UC1; compressedDepth png"`` or ``"32FC1; compressedDepth"``):

- a 12-byte config header: ``int32 format`` (0 = INV_DEPTH) then ``float32 depthParam[2]``
  (quantisation A, B), little-endian, then a PNG;
- ``16UC1``: the PNG holds the millimetre values themselves (0 = invalid);
- ``32FC1``: the PNG holds 16-bit *inverse* depth q = A / z + B; z = A / (q - B), and q = 0
  means invalid (decoded as NaN, which `edge.preprocess` treats as invalid like 0).

Old publishers wrote no header; a PNG found at offset 0 is accepted too. ``rvl`` (the newer
run-length codec) is refused with a one-line error. A plain ``png`` CompressedImage of one
16-bit channel is read as 16UC1 millimetres. Decoding uses OpenCV (already an edge dependency).
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

import numpy as np

from edge import rosmsg
from edge.errors import McapDataError

__all__ = ["COMPRESSED_IMAGE_TYPES", "CompressedImage", "decode_compressed_image", "decompress_depth",
           "encode_compressed_depth", "png_size"]

COMPRESSED_IMAGE_TYPES = frozenset({"sensor_msgs/msg/CompressedImage", "sensor_msgs/CompressedImage"})
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
_HEADER = struct.Struct("<iff")


@dataclass
class CompressedImage:
    stamp_ns: int
    frame_id: str
    format: str
    data: memoryview


def decode_compressed_image(buf: bytes | memoryview, what: str = "CompressedImage") -> CompressedImage:
    """Parse a CDR sensor_msgs/msg/CompressedImage without copying its data."""
    r = rosmsg.CdrReader(buf, what)
    stamp_ns, frame_id = r.header()
    fmt = r.string()
    return CompressedImage(stamp_ns, frame_id, fmt, r.blob())


def png_size(png: bytes) -> tuple[int, int] | None:
    """(width, height) from a PNG's IHDR chunk, without decoding; None when there is no IHDR."""
    if len(png) < 24 or png[:8] != PNG_MAGIC or png[12:16] != b"IHDR":
        return None
    w, h = struct.unpack_from(">II", png, 16)
    return w, h


def decompress_depth(
    msg: CompressedImage, what: str, max_frame: tuple[int, int] | None = None
) -> tuple[np.ndarray, str]:
    """(H x W array, pixel encoding '16UC1' or '32FC1') of a compressed depth message.

    ``max_frame`` (width, height): a PNG claiming more is refused from its header, before
    decoding (a few kB of PNG can hold a 65535 x 65535 image of zeros).
    """
    import cv2

    fmt = msg.format.strip()
    low = fmt.lower()
    if "rvl" in low:
        raise McapDataError(f"{what}: compressedDepth 'rvl' is not supported; republish with png (format '{fmt}')")
    raw = bytes(msg.data)
    depth_enc = "32FC1" if low.startswith("32fc1") else "16UC1"
    a = b = None
    if raw[:8] == PNG_MAGIC:
        png = raw
    elif raw[12:20] == PNG_MAGIC:
        _, a, b = _HEADER.unpack_from(raw, 0)
        png = raw[12:]
    else:
        raise McapDataError(
            f"{what}: CompressedImage format '{fmt}' holds no PNG (first bytes {raw[:4]!r}); depth must be "
            "compressedDepth png or a 16-bit png"
        )
    size = png_size(png)
    if size is None:
        raise McapDataError(f"{what}: the PNG of this compressed depth image has no IHDR header: corrupt")
    if max_frame is not None and (size[0] > max_frame[0] or size[1] > max_frame[1]):
        raise McapDataError(
            f"{what}: frame is {size[0]}x{size[1]}, larger than the {max_frame[0]}x{max_frame[1]} limit "
            "(`max_frame`); raise the limit if the camera really is that large"
        )
    img = cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise McapDataError(f"{what}: the PNG of this compressed depth image is corrupt")
    if img.dtype != np.uint16 or img.ndim != 2:
        raise McapDataError(
            f"{what}: compressed image is {img.dtype} with {1 if img.ndim == 2 else img.shape[2]} channels; "
            "depth must be one 16-bit channel (compressedDepth)"
        )
    if depth_enc == "16UC1":
        return img, "16UC1"
    if a is None:
        raise McapDataError(f"{what}: 32FC1 compressedDepth without its quantisation header cannot be decoded")
    q = img.astype(np.float32)
    with np.errstate(divide="ignore", invalid="ignore"):
        z = np.float32(a) / (q - np.float32(b))
    z[img == 0] = np.nan
    return z.astype(np.float32), "32FC1"


def encode_compressed_depth(stamp_ns: int, frame_id: str, depth_mm: np.ndarray) -> bytes:
    """CDR CompressedImage of 16UC1 millimetres as compressed_depth_image_transport writes it."""
    import cv2

    ok, png = cv2.imencode(".png", np.ascontiguousarray(depth_mm, dtype=np.uint16))
    if not ok:  # pragma: no cover
        raise McapDataError("PNG encoding failed")
    data = _HEADER.pack(0, 0.0, 0.0) + png.tobytes()
    w = rosmsg._W()
    w.header(stamp_ns, frame_id)
    w.string("16UC1; compressedDepth png")
    w.u32(len(data))
    w.raw(data)
    return w.bytes()

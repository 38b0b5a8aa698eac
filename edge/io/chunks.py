"""Bounded decompression: no chunk of a recording inflates past what its header declares.

Why: a chunk header's uncompressed size is a claim, not a fact; a few kB of zstd, lz4 or bz2 can
inflate to gigabytes. Every path that decompresses recording data goes through here: our MCAP
walker (`_decompress_chunk`, streamed, stops one byte past the declared size), and, before
``rosbags`` (which trusts headers) opens a bag, a pre-pass over a ROS 2 bag's MCAP chunks
(`_check_bag_chunks`) or a ROS 1 ``.bag``'s records (`_check_ros1_chunks`). A chunk declaring more
than the limit is refused from its header alone. `_Damage` carries the byte offset into the
reader's one-line message; `_ClampedFile` keeps corrupt length fields from over-reading.
"""

from __future__ import annotations

import os
import struct
from pathlib import Path

from mcap.records import Chunk
from mcap.stream_reader import StreamReader

from edge.errors import McapDataError

MAX_CHUNK_BYTES = 256 * 1024 * 1024


class _Damage(Exception):
    """Raised by the record walker; carries the byte offset for the user-facing message."""

    def __init__(self, offset: int, what: str) -> None:
        super().__init__(what)
        self.offset = offset
        self.what = what


class _ClampedFile:
    """File wrapper whose reads never ask for more than what is left of the file.

    A corrupt length field would otherwise make the buffered reader allocate gigabytes before
    discovering that the bytes are not there.
    """

    def __init__(self, fh, size: int) -> None:
        self._fh = fh
        self.size = size
        self.pos = 0

    def read(self, n: int = -1) -> bytes:
        left = self.size - self.pos
        if n is None or n < 0 or n > left:
            n = left
        data = self._fh.read(n)
        self.pos += len(data)
        return data


def _check_declared(declared: int, limit: int, offset: int) -> None:
    """Refuse, from the header alone, a chunk declaring more uncompressed bytes than ``limit``."""
    if declared > limit:
        raise _Damage(
            offset, f"chunk claims {declared} bytes uncompressed, more than the {limit >> 20} MiB limit: corrupt"
        )


def _inflates_past(comp: str, declared: int) -> str:
    return f"{comp} chunk decompresses to more than the {declared} bytes its header declares: corrupt"


def _decompress_chunk(chunk: Chunk, offset: int, limit: int) -> bytes:
    """The chunk's records, decompressed by streaming and never past the size its header declares.

    The header is not trusted: decompression stops one byte past the declared size (then the
    chunk is damage), so a compression bomb costs at most ``min(declared, limit)`` bytes.
    """
    declared = chunk.uncompressed_size
    _check_declared(declared, limit, offset)
    comp = chunk.compression
    try:
        if comp == "":
            return chunk.data
        if comp == "zstd":
            import zstandard

            claimed = zstandard.frame_content_size(chunk.data)  # -1: not in the frame header
            if claimed > declared:  # rosbags' reader would allocate this much
                raise _Damage(offset, f"zstd frame claims {claimed} bytes, its chunk header {declared}: corrupt")
            parts: list[bytes] = []
            got = 0
            with zstandard.ZstdDecompressor().stream_reader(chunk.data, read_across_frames=True) as r:
                while got <= declared:
                    piece = r.read(declared + 1 - got)
                    if not piece:
                        break
                    parts.append(piece)
                    got += len(piece)
            data = parts[0] if len(parts) == 1 else b"".join(parts)
            parts.clear()
        elif comp == "lz4":
            import lz4.frame

            claimed = lz4.frame.get_frame_info(chunk.data).get("content_size", 0)  # 0: not in the header
            if claimed > declared:
                raise _Damage(offset, f"lz4 frame claims {claimed} bytes, its chunk header {declared}: corrupt")
            d = lz4.frame.LZ4FrameDecompressor()
            data = d.decompress(chunk.data, max_length=declared + 1)
            if len(data) <= declared and not d.eof:
                raise _Damage(offset, "lz4 chunk data ends before its frame does: truncated or corrupt")
        else:
            raise _Damage(offset, f"chunk compression '{comp[:40]}' is not supported (zstd, lz4 or none)")
    except _Damage:
        raise
    except Exception as exc:  # zstd/lz4 errors on corrupt data
        raise _Damage(offset, f"{comp} chunk data is corrupt: it does not decompress ({type(exc).__name__}: {str(exc)[:120]})") from None
    if len(data) > declared:
        raise _Damage(offset, _inflates_past(comp, declared))
    if len(data) < declared:
        raise _Damage(offset, f"{comp} chunk decompresses to {len(data)} bytes, its header declares {declared}: corrupt")
    return data


# ---------------------------------------------------------------------------- decoders


def _check_bag_chunks(bag_dir: Path, limit: int) -> None:
    """Decompress every chunk of a ROS 2 bag's MCAP files within our bounds before ``rosbags`` does.

    ``rosbags`` decompresses a chunk in one call, trusting its headers; a few kB can claim
    gigabytes. This pass (`_decompress_chunk`: streamed, stops past the declared size) finds
    such a chunk first, at the cost of decompressing each chunk twice.
    """
    for f in sorted(bag_dir.rglob("*.mcap")):
        if not f.is_file():
            continue  # (a FIFO is refused by `edge.io.bags` with its name; opening it here would block)
        size = f.stat().st_size
        with open(f, "rb") as raw:
            fh = _ClampedFile(raw, size)
            records = StreamReader(fh, emit_chunks=True, validate_crcs=False, record_size_limit=size).records
            while True:
                start = fh.pos
                try:
                    rec = next(records)
                except StopIteration:
                    break
                except Exception:  # damage that is not a bomb: rosbags reports it in its own words
                    break
                if isinstance(rec, Chunk):
                    try:
                        _decompress_chunk(rec, start, limit)
                    except _Damage as d:
                        raise McapDataError(f"{f}: damaged at byte {d.offset} of {size}: {d.what}") from None


ROS1_MAGIC = b"#ROSBAG V2.0\n"
_ROS1_OP_CHUNK = 5
_INFLATE_STEP = 1 << 20  # decompressed bytes are counted in steps of this size, never kept


def _ros1_fields(header: bytes, offset: int) -> dict[bytes, bytes]:
    """The ``name=value`` fields of one ROS 1 record header; `_Damage` where a length overruns it."""
    fields: dict[bytes, bytes] = {}
    pos = 0
    while pos < len(header):
        if pos + 4 > len(header):
            raise _Damage(offset, "record header ends inside a field length: corrupt")
        (n,) = struct.unpack_from("<I", header, pos)
        pos += 4
        if n > len(header) - pos:
            raise _Damage(offset, f"record header field of {n} bytes overruns its header: corrupt")
        name, eq, value = header[pos:pos + n].partition(b"=")
        if not eq:
            raise _Damage(offset, "record header field without '=': corrupt")
        fields[name] = value
        pos += n
    return fields


def _ros1_inflated_size(comp: str, fh, n: int, declared: int, offset: int) -> int:
    """How many bytes the ``n`` compressed bytes at ``fh`` inflate to, counting at most ``declared + 1``.

    Streamed both ways in 1 MiB steps and nothing kept, so memory stays ~2 MiB whatever the chunk.
    What is counted is what ``rosbags`` would inflate: ``bz2.decompress`` decodes every stream
    (ignoring trailing bytes that are not one), so a bomb cannot hide behind a small first
    stream; ``lz4.frame.decompress`` decodes the first frame only.
    """
    if comp == "bz2":
        import bz2

        new = bz2.BZ2Decompressor
    else:
        import lz4.frame

        new = lz4.frame.LZ4FrameDecompressor
    d = new()
    got, left, pending, streams = 0, n, b"", 1
    try:
        while True:
            if not pending and left and d.needs_input:
                pending = fh.read(min(_INFLATE_STEP, left))
                if not pending:
                    raise _Damage(offset, f"file ends inside the {comp} chunk data: truncated")
                left -= len(pending)
            out = d.decompress(pending, max_length=min(_INFLATE_STEP, declared + 1 - got))
            pending = b""
            got += len(out)
            if got > declared:
                return got
            if d.eof:
                pending = d.unused_data
                if comp != "bz2" or not (pending or left):
                    return got
                d, streams = new(), streams + 1
            elif d.needs_input and not left and not out:
                raise _Damage(offset, f"{comp} chunk data ends before its stream does: truncated or corrupt")
    except _Damage:
        raise
    except Exception as exc:  # bz2/lz4 errors on corrupt data
        if streams > 1:  # bz2.decompress ignores trailing data that is not a bz2 stream
            return got
        raise _Damage(
            offset, f"{comp} chunk data is corrupt: it does not decompress ({type(exc).__name__}: {str(exc)[:120]})"
        ) from None


def _check_ros1_chunks(path: Path, limit: int) -> None:
    """Inflate every compressed chunk of a ROS 1 ``.bag`` within our bounds before ``rosbags`` does.

    ``rosbags`` decompresses a ROS 1 chunk (bz2, or lz4 frame format) in one call, trusting
    nothing and allocating whatever it inflates to: a few hundred bytes can become gigabytes.
    One pass over the records (u32 header length, header, u32 data length, data), never reading
    past the file: each record's lengths must fit in what is left of it; a chunk (op 0x05) whose
    header declares more than ``limit`` uncompressed bytes is refused from its header, and a
    compressed one is read and inflated by streaming, in 1 MiB steps (nothing kept), and refused
    once it passes its declared ``size``. Uncompressed chunks are skipped, not read, so the cost
    is a second read and decompression of compressed bags only (roughly doubling their open
    time); uncompressed bags cost one header read per record.

    A file not starting with the ROS 1 magic is left to ``rosbags`` (its own one-line message).
    """
    size = path.stat().st_size
    try:
        with open(path, "rb") as fh:
            if fh.read(len(ROS1_MAGIC)) != ROS1_MAGIC:
                return
            pos = len(ROS1_MAGIC)
            while pos < size:
                start = pos
                if size - pos < 4:
                    raise _Damage(start, "file ends inside a record's header length: truncated")
                (hlen,) = struct.unpack("<I", fh.read(4))
                pos += 4
                if hlen > size - pos - 4:
                    raise _Damage(start, f"record header of {hlen} bytes does not fit in the file: truncated or corrupt")
                header = fh.read(hlen)
                (dlen,) = struct.unpack("<I", fh.read(4))
                pos += hlen + 4
                if dlen > size - pos:
                    raise _Damage(start, f"record data of {dlen} bytes does not fit in the file: truncated or corrupt")
                fields = _ros1_fields(header, start)
                op = fields.get(b"op", b"")
                if op[:1] == bytes([_ROS1_OP_CHUNK]) and len(op) == 1:
                    raw_size = fields.get(b"size", b"")
                    if len(raw_size) != 4:
                        raise _Damage(start, "chunk header has no 4-byte size field: corrupt")
                    (declared,) = struct.unpack("<I", raw_size)
                    comp = fields.get(b"compression", b"none").decode("ascii", "replace")
                    _check_declared(declared, limit, start)
                    if comp in ("bz2", "lz4"):
                        here = fh.tell()
                        if _ros1_inflated_size(comp, fh, dlen, declared, start) > declared:
                            raise _Damage(start, _inflates_past(comp, declared))
                        fh.seek(here + dlen)
                        pos += dlen
                        continue
                fh.seek(dlen, os.SEEK_CUR)
                pos += dlen
    except _Damage as d:
        raise McapDataError(f"{path}: damaged at byte {d.offset} of {size}: {d.what}") from None
    except PermissionError:
        raise McapDataError(f"{path}: permission denied") from None

"""ROS 1 ``.bag``, ROS 2 ``.db3`` and ROS 2 bag directories as the message stream of an MCAP file.

Why an adapter and not a second reader: the depth stream must mean the same thing whatever the
container: the same topic detection, the same decoding, the same one-line errors, the same
invalid-pixel handling. So this module only turns a bag into what `edge.io.reader` walks in an
MCAP file: ``(mcap Schema, mcap Channel, mcap Message)`` triples in time order, with every
message as ROS 2 CDR (ROS 1 messages are converted by ``rosbags``' typestore, byte-exact field by
field). Everything after that (topic choice, label pairing, compressedDepth, ``--out``) is the
MCAP code path.

What is a bag here (`is_bag`):
- a file ending in ``.bag`` (ROS 1; several split files are separate recordings),
- a file ending in ``.db3`` (one ROS 2 sqlite3 storage file),
- a directory holding ``metadata.yaml`` (a ROS 2 bag of sqlite3 or MCAP files, split or not).

``rosbags`` is an optional dependency (``pip install 'depthseg[ros]'``); without it, a bag gives
one line saying what to install.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

from mcap.records import Channel, Message, Schema

from edge.errors import McapDataError
from edge.io.paths import special_kind

__all__ = ["is_bag", "BagSource", "open_bag", "bag_kind"]

INSTALL_HINT = "pip install 'depthseg[ros]' (or: pip install rosbags)"


def bag_kind(path: Path) -> str | None:
    """'ros1', 'ros2-db3', 'ros2-dir' or None (not a bag: an MCAP file or something else)."""
    if path.is_dir():
        return "ros2-dir" if (path / "metadata.yaml").is_file() else None
    suffix = path.suffix.lower()
    if suffix == ".bag":
        return "ros1"
    if suffix == ".db3":
        return "ros2-db3"
    return None


def is_bag(path: str | Path) -> bool:
    return bag_kind(Path(path)) is not None


def _rosbags():
    try:
        from rosbags.highlevel import AnyReader, AnyReaderError
        from rosbags.typesys import Stores, get_typestore
    except ImportError:
        raise McapDataError(f"reading ROS bags needs the rosbags package: {INSTALL_HINT}") from None
    return AnyReader, AnyReaderError, Stores, get_typestore


def _one_line(exc: BaseException) -> str:
    text = " ".join(str(exc).split()) or type(exc).__name__
    return text[:200]


class BagSource:
    """One bag, opened with ``rosbags``; `messages` yields MCAP records (re-iterable)."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.kind = bag_kind(path)
        if self.kind is None:
            raise McapDataError(f"{path}: not a ROS bag (.bag, .db3 or a directory with metadata.yaml)")
        if self.kind == "ros1" and path.is_file() and path.stat().st_size == 0:
            raise McapDataError(f"{path}: empty file (0 bytes), not a ROS 1 bag")
        for f in path.rglob("*") if path.is_dir() else ():
            kind = special_kind(f)
            if kind is not None:  # rosbags would open it and block on a FIFO with no writer
                raise McapDataError(f"{path}: {f.name} in the bag directory is a {kind}, not a file; copy the data first")
        self.size = sum(f.stat().st_size for f in path.rglob("*") if f.is_file()) if path.is_dir() else path.stat().st_size
        self.schemas: dict[int, Schema] = {}
        self.channels: dict[int, Channel] = {}
        self.counts: dict[int, int] = {}
        self._msgtype: dict[int, str] = {}
        self._ros2_types: set[int] = set()  # ROS 1 connections converted with the ROS 2 type store
        _, _, Stores, get_typestore = _rosbags()
        self._ros2 = get_typestore(Stores.LATEST)
        reader = self._open()
        try:
            self.is_ros1 = not reader.is2
            for i, conn in enumerate(reader.connections, start=1):
                data = conn.msgdef.data.encode() if conn.msgdef and conn.msgdef.data else b""
                enc = "ros2idl" if data.startswith(b"=" * 80 + b"\nIDL: ") else "ros2msg"
                if self.is_ros1 and self._same_as_ros2(reader.typestore, conn.msgtype):
                    # ROS 1 -> ROS 2 wire format (the Header loses its seq) with the ROS 2 definition,
                    # so the CDR and the schema agree with what a ROS 2 recorder writes
                    data = self._ros2.generate_msgdef(conn.msgtype, ros_version=2)[0].encode()
                    self._ros2_types.add(i)
                self.schemas[i] = Schema(id=i, name=conn.msgtype, encoding=enc, data=data)
                fmt = getattr(conn.ext, "serialization_format", "cdr") if not self.is_ros1 else "cdr"
                self.channels[i] = Channel(id=i, topic=conn.topic, message_encoding=fmt, schema_id=i, metadata={})
                self.counts[i] = int(conn.msgcount)
                self._msgtype[i] = conn.msgtype
        finally:
            reader.close()

    def _same_as_ros2(self, typestore, msgtype: str) -> bool:
        if msgtype not in self._ros2.fielddefs:
            return False
        try:
            from rosbags.convert.converter import is_same_wireformat

            return bool(is_same_wireformat(typestore, self._ros2, msgtype, msgtype))
        except Exception:  # a type the ROS 2 store describes differently: keep the bag's own definition
            return False

    def _open(self):
        AnyReader, AnyReaderError, Stores, get_typestore = _rosbags()
        try:
            reader = AnyReader([self.path], default_typestore=get_typestore(Stores.LATEST))
            reader.open()
        except (AnyReaderError, FileNotFoundError, OSError, ValueError, KeyError) as exc:
            what = {"ros1": "ROS 1 bag", "ros2-db3": "ROS 2 sqlite3 bag", "ros2-dir": "ROS 2 bag"}[self.kind or "ros2-dir"]
            raise McapDataError(f"{self.path}: unreadable {what} ({_one_line(exc)})") from None
        except Exception as exc:  # rosbags raises many types on damaged files; all are data errors here
            raise McapDataError(f"{self.path}: unreadable bag ({type(exc).__name__}: {_one_line(exc)})") from None
        return reader

    def summary(self) -> tuple[dict[int, Channel], dict[int, Schema], dict[int, int]]:
        """(channels, schemas, message counts) as `edge.io.reader` reads them from an MCAP summary."""
        return dict(self.channels), dict(self.schemas), dict(self.counts)

    def messages(self, position: list[int] | None = None) -> Iterator[tuple[Schema, Channel, Message]]:
        """All messages in time order as ROS 2 CDR; `McapDataError` (one line) where the bag breaks.

        ``position`` (a one-element list) is advanced by each message's size, so a caller can stop
        peeking after so many bytes as it does in an MCAP file.
        """
        reader = self._open()
        seq: dict[int, int] = {}
        try:
            ids = {id(c): i for i, c in enumerate(reader.connections, start=1)}
            it = reader.messages()
            while True:
                try:
                    conn, t, raw = next(it)
                except StopIteration:
                    return
                except Exception as exc:  # damage inside the bag: truncated chunk, bad index, ...
                    raise McapDataError(f"{self.path}: damaged bag ({type(exc).__name__}: {_one_line(exc)})") from None
                cid = ids[id(conn)]
                data: Any = raw
                if self.is_ros1:
                    try:
                        store = self._ros2 if cid in self._ros2_types else reader.typestore
                        data = store.ros1_to_cdr(raw, self._msgtype[cid])
                    except Exception as exc:
                        raise McapDataError(
                            f"{self.path}: {conn.topic} message at {t} ns is not a valid {self._msgtype[cid]} "
                            f"({type(exc).__name__}: {_one_line(exc)})"
                        ) from None
                n = seq.get(cid, 0)
                seq[cid] = n + 1
                if position is not None:
                    position[0] += len(data)
                yield (
                    self.schemas[cid], self.channels[cid],
                    Message(channel_id=cid, sequence=n, log_time=int(t), publish_time=int(t), data=bytes(data)),
                )
        finally:
            reader.close()


def open_bag(path: str | Path) -> BagSource | None:
    """A `BagSource` when ``path`` is a bag, else None."""
    p = Path(path)
    if not p.exists():
        return None
    return BagSource(p) if bag_kind(p) else None

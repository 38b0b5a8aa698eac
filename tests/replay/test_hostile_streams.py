"""Hostile recordings (issue 11): bounded memory, no hangs, one line, never a traceback.

Each file here is crafted record by record, the way an attacker would: a chunk that lies about
its size, a frame that is valid but huge, a channel id that changes meaning, a FIFO, a clock
that jumps 116 days. The reader and replay must refuse each with one `DepthsegError` line (or,
for the clock, keep going) without allocating what the file claims.
"""

from __future__ import annotations

import json
import os
import resource
import struct
import time
import tracemalloc
from pathlib import Path

import numpy as np
import pytest
from mcap.data_stream import RecordBuilder
from mcap.records import Channel, Chunk, DataEnd, Footer, Header, Message, Schema
from mcap.writer import Writer
from replaygen import FakeSegmenter, write_ros2

from edge import rosmsg
from edge.errors import ConfigError, DataError, DepthsegError, McapDataError
from edge.io import Frame
from edge.io.reader import open_depth_stream
from replay.cli import main as replay_main
from replay.replay import replay

MAGIC = b"\x89MCAP0\r\n"
IMG = Schema(id=1, name=rosmsg.IMAGE_TYPE, encoding="ros2msg", data=rosmsg.IMAGE_MSGDEF.encode())
DEPTH = Channel(id=1, schema_id=1, topic="/cam/depth", message_encoding="cdr", metadata={})


def one_line(exc: BaseException) -> str:
    msg = str(exc)
    assert "\n" not in msg and 0 < len(msg) < 600, msg
    return msg


def cli(capsys, *args) -> tuple[int, str]:
    rc = replay_main([str(a) for a in args])
    err = capsys.readouterr().err
    return rc, err


def assert_cli_error(rc: int, err: str, *needles: str) -> str:
    lines = [ln for ln in err.splitlines() if "error:" in ln]
    assert rc == 2 and len(lines) == 1 and "Traceback" not in err, err
    for n in needles:
        assert n in lines[0], lines[0]
    return lines[0]


def records(*recs) -> bytes:
    b = RecordBuilder()
    for r in recs:
        r.write(b)
    return b.end()


def mcap_file(path: Path, *recs) -> Path:
    path.write_bytes(MAGIC + records(Header(profile="ros2", library="hostile"), *recs, DataEnd(0), Footer(0, 0, 0)) + MAGIC)
    return path


def image_msg(t: int, arr: np.ndarray, enc: str, channel: int = 1, stamp: int | None = None) -> Message:
    return Message(channel_id=channel, sequence=0, log_time=t, publish_time=t,
                   data=rosmsg.encode_image(t if stamp is None else stamp, "cam", arr, enc))


# ------------------------------------------------------------------ decompression bombs


def _zeros(n: int, block: bytes):
    while n > 0:
        yield block[: min(n, len(block))]
        n -= len(block)


def _bomb_chunk(compression: str, n_zeros: int, pledge: bool, payload: bytes = b"", declared: int = 64) -> Chunk:
    """A chunk holding a schema, a channel and one message of ``payload`` + ``n_zeros`` zero bytes
    (compressed by streaming: the zeros never exist in memory), claiming ``declared`` bytes."""
    size = len(payload) + n_zeros
    prefix = records(IMG, DEPTH) + struct.pack("<BQHIQQ", 0x05, 2 + 4 + 8 + 8 + size, 1, 0, 1, 1) + payload
    block = bytes(1 << 20)
    if compression == "zstd":
        import zstandard

        c = zstandard.ZstdCompressor(level=1).compressobj(size=len(prefix) + n_zeros if pledge else -1)
        parts = [c.compress(prefix)] + [c.compress(b) for b in _zeros(n_zeros, block)] + [c.flush()]
    else:
        import lz4.frame

        c = lz4.frame.LZ4FrameCompressor()
        parts = [c.begin(source_size=len(prefix) + n_zeros if pledge else 0), c.compress(prefix)]
        parts += [c.compress(b) for b in _zeros(n_zeros, block)] + [c.flush()]
    return Chunk(compression=compression, data=b"".join(parts), message_start_time=1, message_end_time=1,
                 uncompressed_crc=0, uncompressed_size=declared if declared >= 0 else len(prefix) + n_zeros)


@pytest.mark.parametrize("compression,pledge", [("zstd", False), ("zstd", True), ("lz4", False), ("lz4", True)])
def test_a_chunk_lying_about_its_size_is_not_inflated(tmp_path, compression, pledge):
    """64 MB of zeros in a chunk that claims 64 bytes (with and without the real size in the
    compressed frame's own header): decompression stops at 65 bytes; one line names the lie."""
    p = mcap_file(tmp_path / "bomb.mcap", Header(profile="", library="x"), _bomb_chunk(compression, 64 << 20, pledge))
    assert p.stat().st_size < 1 << 20
    rss0 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    tracemalloc.start()
    try:
        with pytest.raises(McapDataError) as e:
            for _ in open_depth_stream(p, topic="/cam/depth"):
                pass
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    grown_mb = (resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - rss0) / 1024
    assert peak < 8 << 20 and grown_mb < 32, (peak, grown_mb)
    msg = one_line(e.value)
    assert "before the damage (byte " in msg, msg
    # a size in the compressed frame's own header is compared first; without one, streaming stops at 65 bytes
    assert ("its chunk header 64: corrupt" if pledge else "more than the 64 bytes its header declares") in msg, msg


def test_a_chunk_claiming_more_than_the_limit_is_refused_unread(tmp_path):
    ch = Chunk(compression="zstd", data=b"\x00" * 16, message_start_time=1, message_end_time=1,
               uncompressed_crc=0, uncompressed_size=1 << 40)
    p = mcap_file(tmp_path / "big.mcap", ch)
    with pytest.raises(McapDataError) as e:
        open_depth_stream(p)
    assert "claims 1099511627776 bytes uncompressed, more than the 256 MiB limit" in one_line(e.value)
    bad = Chunk(compression="brotli", data=b"x", message_start_time=1, message_end_time=1, uncompressed_crc=0,
                uncompressed_size=1)
    with pytest.raises(McapDataError) as e:
        open_depth_stream(mcap_file(tmp_path / "br.mcap", bad))
    assert "compression 'brotli' is not supported" in one_line(e.value)


# ------------------------------------------------------------------ frame size


@pytest.mark.parametrize("side", [4100, pytest.param(8192, marks=pytest.mark.slow)])
def test_a_valid_huge_frame_is_refused_from_its_header(tmp_path, capsys, linear_onnx, side):
    """The issue's 23 kB file: a real 8192 x 8192 16UC1 frame of zeros in a zstd chunk (4100 x 4100
    in the fast run). It is refused by its header before it becomes an array or reaches onnxruntime."""
    n = side * side * 2
    cdr = rosmsg._W()
    cdr.header(1, "cam")
    for v in (side, side):
        cdr.u32(v)
    cdr.string("16UC1")
    cdr.u8(0)
    cdr.u32(side * 2)
    cdr.u32(n)
    p = mcap_file(tmp_path / "huge.mcap", _bomb_chunk("zstd", n, True, payload=cdr.bytes(), declared=-1))
    assert p.stat().st_size < 100_000
    t0 = time.perf_counter()
    rc, err = cli(capsys, p, "--model", linear_onnx)
    assert_cli_error(rc, err, f"frame is {side}x{side}, larger than the 4096x4096 limit (--max-frame)")
    assert time.perf_counter() - t0 < 30


def test_frame_limit_is_a_parameter_and_covers_every_decoder(tmp_path):
    rec = write_ros2(tmp_path / "r.mcap", n=2, size=(24, 32))
    with pytest.raises(McapDataError) as e:
        list(open_depth_stream(rec.path, max_frame=(31, 24)))
    assert "frame is 32x24, larger than the 31x24 limit" in one_line(e.value)
    assert len(list(open_depth_stream(rec.path, max_frame=(32, 24)))) == 2
    for bad in [(0, 5), (5,), "4096", (1.5, 3), None]:
        with pytest.raises(ConfigError):
            open_depth_stream(rec.path, max_frame=bad)
    # a compressedDepth PNG is sized from its IHDR, never decoded: 65535 x 65535 of zeros is tiny as PNG
    from edge.io.compressed import PNG_MAGIC, CompressedImage, decompress_depth

    ihdr = PNG_MAGIC + struct.pack(">I", 13) + b"IHDR" + struct.pack(">IIBBBBB", 65535, 65535, 16, 0, 0, 0, 0)
    msg = CompressedImage(0, "cam", "16UC1; compressedDepth png", memoryview(bytes(12) + ihdr + bytes(16)))
    with pytest.raises(McapDataError) as e:
        decompress_depth(msg, "m", max_frame=(4096, 4096))
    assert "65535x65535, larger than the 4096x4096 limit" in one_line(e.value)


# ------------------------------------------------------------------ special files and output paths


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="no FIFOs here")
def test_fifos_are_refused_at_once(tmp_path, capsys):
    fifo = tmp_path / "rec.mcap"
    os.mkfifo(fifo)
    with pytest.raises(DataError) as e:
        open_depth_stream(fifo)
    assert "is a FIFO, not a regular file" in one_line(e.value)
    rc, err = cli(capsys, fifo)
    assert_cli_error(rc, err, "is a FIFO")
    bag = tmp_path / "bagdir"
    bag.mkdir()
    (bag / "metadata.yaml").write_text("rosbag2_bagfile_information: {}\n")
    os.mkfifo(bag / "bag_0.mcap")
    with pytest.raises(McapDataError) as e:
        open_depth_stream(bag)
    assert "bag_0.mcap in the bag directory is a FIFO" in one_line(e.value)


def test_out_must_not_be_the_recording_or_a_special_file(tmp_path, capsys):
    rec = write_ros2(tmp_path / "in.mcap", n=2)
    before = rec.path.read_bytes()
    rc, err = cli(capsys, rec.path, "--out", rec.path)
    assert_cli_error(rc, err, "--out", "would overwrite the input")
    link = tmp_path / "link.mcap"
    link.symlink_to(rec.path)
    rc, err = cli(capsys, rec.path, "--out", link)
    assert_cli_error(rc, err, "would overwrite the input")
    rc, err = cli(capsys, rec.path, "--out", "/dev/null")
    assert_cli_error(rc, err, "--out", "is a device")
    assert rec.path.read_bytes() == before


# ------------------------------------------------------------------ pacing


def _frames(stamps: list[int]) -> list[Frame]:
    d = np.full((8, 8), 0.3, np.float32)
    return [Frame(depth=d, stamp_ns=t) for t in stamps]


def test_pacing_skips_a_116_day_gap_and_says_so_once():
    day = 86_400 * 10**9
    t = 1_700_000_000 * 10**9
    stamps = [t, t + 10**7, t + 116 * day, t + 116 * day + 10**7, t + 2 * day, t + 2 * day + 10**7]  # and back
    notes: list[str] = []
    t0 = time.perf_counter()
    s = replay(_frames(stamps), FakeSegmenter(), rate=1.0, on_note=notes.append)
    assert time.perf_counter() - t0 < 5
    assert s.frames == 6 and s.gaps_skipped == 2 and len(notes) == 1
    assert "jumps by 1.00224e+07 s" in notes[0] and "gaps longer than 1 s" in notes[0]
    assert s.to_dict()["gaps_skipped"] == 2


@pytest.mark.parametrize("rate", ["1e-300", "0", "-1", "inf", "nan", "1e300"])
def test_unusable_rates_are_one_line(tmp_path, capsys, rate):
    rec = write_ros2(tmp_path / "in.mcap", n=2)
    rc, err = cli(capsys, rec.path, "--rate", rate)
    assert_cli_error(rc, err, "--rate must be a number from 0.001 to 1000")
    with pytest.raises(ConfigError):
        replay(_frames([1, 2]), FakeSegmenter(), rate=float(rate))


# ------------------------------------------------------------------ fields that used to crash


def _json_file(path: Path, schema: str, payloads: list[tuple[str, bytes]]) -> Path:
    with open(path, "wb") as fh:
        w = Writer(fh)
        w.start("", "hostile")
        sids, cids = {}, {}
        for i, (topic, data) in enumerate(payloads):
            name = schema if topic == "/cam/depth" else "foxglove.CameraCalibration"
            if name not in sids:
                sids[name] = w.register_schema(name, "jsonschema", b"{}")
            if topic not in cids:
                cids[topic] = w.register_channel(topic, "json", sids[name])
            w.add_message(cids[topic], 1000 + i, data, 1000 + i)
        w.finish()
    return path


def _raw_json(**over) -> bytes:
    import base64

    d = {"timestamp": {"sec": 1, "nsec": 0}, "frame_id": "cam", "width": 2, "height": 2, "encoding": "32FC1",
         "step": 8, "data": base64.b64encode(np.full((2, 2), 0.3, np.float32).tobytes()).decode()}
    d.update(over)
    return json.dumps(d).encode().replace(b'"INF"', b"1e400")


@pytest.mark.parametrize("field", ["width", "height", "step", "timestamp"])
def test_json_rawimage_with_1e400_is_one_line(tmp_path, field):
    over = {"timestamp": {"sec": "INF", "nsec": 0}} if field == "timestamp" else {field: "INF"}
    p = _json_file(tmp_path / "j.mcap", "foxglove.RawImage", [("/cam/depth", _raw_json(**over))])
    with pytest.raises(McapDataError) as e:
        list(open_depth_stream(p, topic="/cam/depth"))
    assert "must be a whole number" in one_line(e.value)


def test_camera_calibration_with_a_string_k_is_ignored_with_one_warning(tmp_path):
    cal = json.dumps({"width": 2, "height": 2, "K": "210 0 1 0 212 1 0 0 1", "D": []}).encode()
    good = json.dumps({"width": 2, "height": 2, "K": [210, 0, 1, 0, 212, 1, 0, 0, 1], "D": [0.1, 0.01, 0.001]}).encode()
    p = _json_file(tmp_path / "c.mcap", "foxglove.RawImage",
                   [("/cam/calibration", cal), ("/cam/depth", _raw_json()), ("/cam/calibration", good),
                    ("/cam/depth", _raw_json()), ("/cam/calibration", cal), ("/cam/depth", _raw_json())])
    warnings: list[str] = []
    s = open_depth_stream(p, on_warning=warnings.append)
    assert s.camera_info is None  # the first calibration is unusable: none
    infos = [fr.info for fr in s]
    assert infos[0] is None and infos[1] == infos[2] and infos[1]["fx"] == 210.0
    assert infos[1]["d"] == [0.1, 0.01, 0.001, 0.0]  # 3 coefficients padded to a length OpenCV takes
    assert len(warnings) == 1 and "camera calibration K must be 9 numbers" in warnings[0]


def test_cameraInfo_with_three_distortion_coefficients_works_for_the_baseline(tmp_path):
    """What `--baseline` does with the frame's CameraInfo: undistorted rays from OpenCV."""
    from edge.baseline import back_project, intrinsics_for

    w = rosmsg._W()
    w.header(5, "cam")
    w.u32(8)
    w.u32(8)
    w.string("plumb_bob")
    w.f64s([0.1, -0.05, 0.01], with_len=True)
    w.f64s([50, 0, 4, 0, 50, 4, 0, 0, 1], with_len=False)
    p = tmp_path / "ci.mcap"
    with open(p, "wb") as fh:
        wr = Writer(fh)
        wr.start("ros2", "hostile")
        ci = wr.register_schema(rosmsg.CAMERA_INFO_TYPE, "ros2msg", b"")
        img = wr.register_schema(IMG.name, IMG.encoding, IMG.data)
        c1 = wr.register_channel("/cam/camera_info", "cdr", ci)
        c2 = wr.register_channel("/cam/depth", "cdr", img)
        wr.add_message(c1, 5, w.bytes(), 5)
        wr.add_message(c2, 5, rosmsg.encode_image(5, "cam", np.full((8, 8), 0.3, np.float32), "32FC1"), 5)
        wr.finish()
    (fr,) = list(open_depth_stream(p))
    assert fr.info["d"] == [0.1, -0.05, 0.01, 0.0]
    pts = back_project(fr.depth, intrinsics_for(fr.depth.shape, fr.info))
    assert pts.shape == (64, 3) and np.isfinite(pts).all()


def test_log_times_after_2038_with_header_stamp_0_write_an_output(tmp_path, capsys, linear_onnx):
    t = 2_300_000_000 * 10**9  # 2042
    d = np.full((24, 32), 0.3, np.float32)
    p = mcap_file(tmp_path / "late.mcap", IMG, DEPTH, *(image_msg(t + i, d, "32FC1", stamp=0) for i in range(2)))
    out = tmp_path / "out.mcap"
    rc = replay_main([str(p), "--model", str(linear_onnx), "--out", str(out)])
    assert rc == 0, capsys.readouterr().err
    from mcap.reader import make_reader

    with open(out, "rb") as fh:
        msgs = [(c.topic, m.log_time, rosmsg.decode_image(m.data).stamp_ns)
                for _, c, m in make_reader(fh).iter_messages() if c.topic == "/depthseg/mask"]
    assert msgs == [("/depthseg/mask", t, 0), ("/depthseg/mask", t + 1, 0)]
    with pytest.raises(McapDataError) as e:  # writing such a stamp into a header is one line, not struct.error
        rosmsg.encode_image(t, "cam", d, "32FC1")
    assert "does not fit a ROS 2 header" in one_line(e.value)


def test_a_damaged_scene_message_is_one_line(tmp_path):
    from edge.io.frames import decode_scene

    for data in (b"\xff\xfe", b"[1, 2]", b"{" * 100_000):
        with pytest.raises(McapDataError) as e:
            decode_scene("json", data)
        one_line(e.value)


# ------------------------------------------------------------------ channel and schema ids


def test_a_channel_id_redefined_mid_file_is_an_error(tmp_path, fake):
    string = Schema(id=2, name=rosmsg.STRING_TYPE, encoding="ros2msg", data=rosmsg.STRING_MSGDEF.encode())
    chatter = Channel(id=1, schema_id=2, topic="/chatter", message_encoding="cdr", metadata={})
    d = np.full((8, 8), 0.3, np.float32)
    p = mcap_file(tmp_path / "redef.mcap", IMG, DEPTH, image_msg(1, d, "32FC1"), image_msg(2, d, "32FC1"), string,
                  chatter, Message(channel_id=1, sequence=0, log_time=3, publish_time=3, data=rosmsg.encode_string("hi")))
    frames = []
    with pytest.raises(McapDataError) as e:
        for fr in open_depth_stream(p):
            frames.append(fr)
    assert len(frames) == 2
    assert "channel id 1 is redefined: /cam/depth (cdr, schema 1) became /chatter (cdr, schema 2)" in one_line(e.value)
    other = Schema(id=1, name=rosmsg.STRING_TYPE, encoding="ros2msg", data=rosmsg.STRING_MSGDEF.encode())
    p2 = mcap_file(tmp_path / "redef2.mcap", IMG, DEPTH, image_msg(1, d, "32FC1"), other, image_msg(2, d, "32FC1"))
    with pytest.raises(McapDataError) as e:
        list(open_depth_stream(p2))
    assert "schema id 1 is redefined" in one_line(e.value)
    # identical repeats (one per chunk, as every writer does) are fine
    p3 = mcap_file(tmp_path / "rep.mcap", IMG, DEPTH, image_msg(1, d, "32FC1"), IMG, DEPTH, image_msg(2, d, "32FC1"))
    assert len(list(open_depth_stream(p3))) == 2


# ------------------------------------------------------------------ output topics


def test_replaying_a_replay_output_never_doubles_a_topic(tmp_path, capsys, linear_onnx):
    rec = write_ros2(tmp_path / "in.mcap", n=2)
    first = tmp_path / "first.mcap"
    assert replay_main([str(rec.path), "--model", str(linear_onnx), "--out", str(first)]) == 0
    capsys.readouterr()
    again = tmp_path / "again.mcap"
    rc, err = cli(capsys, first, "--model", linear_onnx, "--out", again)
    assert_cli_error(rc, err, "already has /depthseg/mask", "--out-namespace", "/depthseg2")
    assert not again.exists()
    assert replay_main([str(first), "--model", str(linear_onnx), "--out", str(again), "--out-namespace", "/depthseg2"]) == 0
    from mcap.reader import make_reader

    with open(again, "rb") as fh:
        topics = [c.topic for c in make_reader(fh).get_summary().channels.values()]
    assert len(topics) == len(set(topics)) and "/depthseg2/mask" in topics and "/depthseg/mask" in topics


# ------------------------------------------------------------------ millimetres as 32FC1


def test_millimetres_in_32fc1_warn_once_and_depth_scale_fixes_them(tmp_path, capsys, linear_onnx):
    d = np.full((24, 32), 300.0, np.float32)
    d[:2] = 0
    p = mcap_file(tmp_path / "mm.mcap", IMG, DEPTH, *(image_msg(10 + i, d, "32FC1") for i in range(3)))
    warnings: list[str] = []
    frames = list(open_depth_stream(p, on_warning=warnings.append))
    assert len(frames) == 3 and len(warnings) == 1
    assert "median of 300 m" in warnings[0] and "looks like millimetres" in warnings[0] and "0.001" in warnings[0]
    warnings.clear()
    frames = list(open_depth_stream(p, depth_scale=0.001, on_warning=warnings.append))
    assert warnings == [] and np.allclose(frames[0].depth[5], 0.3)
    rc = replay_main([str(p), "--model", str(linear_onnx)])
    err = capsys.readouterr().err
    assert rc == 0 and sum("looks like millimetres" in ln for ln in err.splitlines()) == 1, err
    assert "--depth-scale" in err
    rc = replay_main([str(p), "--model", str(linear_onnx), "--depth-scale", "0.001"])
    assert rc == 0 and "millimetres" not in capsys.readouterr().err
    for bad in (0.0, -1.0, float("nan"), float("inf")):
        with pytest.raises(ConfigError):
            open_depth_stream(p, depth_scale=bad)
    from edge.eval_cli import parser as eval_parser
    from edge.tune_cli import parser as tune_parser

    for parser in (eval_parser, tune_parser):
        assert parser.parse_args(["--data", "x", "--depth-scale", "0.001"]).depth_scale == 0.001


def test_every_error_here_is_a_depthseg_error():
    """The CLIs turn exactly these into one line; anything else would be a traceback."""
    assert issubclass(McapDataError, DepthsegError) and issubclass(ConfigError, DepthsegError)


def test_a_bomb_inside_a_ros2_bag_directory_is_found_before_rosbags_reads_it(tmp_path):
    """rosbags decompresses a chunk in one call; our bounded pass over the bag's MCAP files runs first."""
    bag = tmp_path / "bag"
    bag.mkdir()
    (bag / "metadata.yaml").write_text("rosbag2_bagfile_information: {}\n")
    mcap_file(bag / "bag_0.mcap", _bomb_chunk("zstd", 16 << 20, True))
    tracemalloc.start()
    try:
        with pytest.raises(McapDataError) as e:
            open_depth_stream(bag)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak < 8 << 20
    assert "bag_0.mcap: damaged at byte" in one_line(e.value) and "zstd frame claims" in str(e.value)


# ------------------------------------------------------------------ ROS 1 .bag chunk bombs


def _ros1_record(data: bytes, **fields: bytes) -> bytes:
    header = b"".join(struct.pack("<I", len(k) + 1 + len(v)) + k.encode() + b"=" + v for k, v in fields.items())
    return struct.pack("<I", len(header)) + header + struct.pack("<I", len(data)) + data


def ros1_bag(path: Path, chunk_data: bytes, compression: str, declared: int) -> Path:
    """``#ROSBAG V2.0``, a bag header record (op 3) and one chunk record (op 5) that lies about its size."""
    bag_header = _ros1_record(
        b" " * 64, op=b"\x03", index_pos=struct.pack("<Q", 0), conn_count=struct.pack("<I", 0),
        chunk_count=struct.pack("<I", 1),
    )
    chunk = _ros1_record(chunk_data, op=b"\x05", compression=compression.encode(), size=struct.pack("<I", declared))
    path.write_bytes(b"#ROSBAG V2.0\n" + bag_header + chunk)
    return path


def _ros1_bomb_compressor(compression: str, n_zeros: int):
    """bz2 / lz4-frame compression of a chunk followed by ``n_zeros`` zero bytes (streamed: the zeros never exist)."""
    if compression == "bz2":
        import bz2

        def start():
            return bz2.BZ2Compressor(9), b""
    else:
        lz4_frame = pytest.importorskip("lz4.frame")

        def start():
            c = lz4_frame.LZ4FrameCompressor()
            return c, c.begin()  # the frame header

    def compress(chunk: bytes) -> bytes:
        c, head = start()
        return head + c.compress(chunk) + b"".join([c.compress(b) for b in _zeros(n_zeros, bytes(1 << 20))] + [c.flush()])

    return compress


def ros1_bomb_bag(path: Path, compression: str, n_zeros: int) -> Path:
    """A well-formed, indexed ROS 1 bag (rosbags' writer) with one 16UC1 depth image, whose only
    chunk declares its honest size but whose compressed data also holds ``n_zeros`` zero bytes:
    rosbags' reader would inflate all of them when it reads the message."""
    rosbag1 = pytest.importorskip("rosbags.rosbag1")
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS1_NOETIC)
    Image = store.types["sensor_msgs/msg/Image"]
    Header = store.types["std_msgs/msg/Header"]
    Time = store.types["builtin_interfaces/msg/Time"]
    img = Image(header=Header(seq=0, stamp=Time(sec=1, nanosec=0), frame_id="cam"), height=2, width=2,
                encoding="16UC1", is_bigendian=0, step=4, data=np.zeros(8, np.uint8))
    w = rosbag1.Writer(path)
    w.set_compression(rosbag1.Writer.CompressionFormat.BZ2 if compression == "bz2" else rosbag1.Writer.CompressionFormat.LZ4)
    with w:
        w.compressor = _ros1_bomb_compressor(compression, n_zeros)
        conn = w.add_connection("/cam/depth", "sensor_msgs/msg/Image", typestore=store)
        w.write(conn, 1_000_000_000, store.serialize_ros1(img, "sensor_msgs/msg/Image"))
    return path


@pytest.mark.parametrize("compression", ["bz2", "lz4"])
def test_a_ros1_bag_chunk_lying_about_its_size_is_refused_before_rosbags_inflates_it(tmp_path, capsys, compression):
    """rosbags inflates a ROS 1 chunk in one call (bz2.decompress / lz4.frame.decompress), trusting
    nothing: a chunk of a few hundred kB that declares ~150 bytes inflates to 48 MB (gigabytes
    with more zeros). Our streamed pass runs first and stops one byte past the declared size."""
    p = ros1_bomb_bag(tmp_path / "bomb.bag", compression, 48 << 20)
    assert p.stat().st_size < 1 << 20
    tracemalloc.start()
    try:
        with pytest.raises(McapDataError) as e:
            for _ in open_depth_stream(p):
                pass
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    print(f"ros1 {compression} bomb: tracemalloc peak {peak / 1e6:.2f} MB")
    assert peak < 50 << 20, peak
    msg = one_line(e.value)
    assert "bomb.bag: damaged at byte " in msg and f"{compression} chunk decompresses to more than the " in msg, msg
    tracemalloc.start()
    try:
        rc, err = cli(capsys, p)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak < 50 << 20, peak
    assert_cli_error(rc, err, "bomb.bag: damaged at byte", "bytes its header declares: corrupt")


def test_a_ros1_bag_chunk_declaring_more_than_the_cap_is_refused_from_its_header(tmp_path, capsys):
    import bz2

    p = ros1_bag(tmp_path / "huge.bag", bz2.compress(b"\0" * 1024), "bz2", 300 << 20)
    tracemalloc.start()
    try:
        with pytest.raises(McapDataError) as e:
            open_depth_stream(p)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak < 50 << 20, peak
    msg = one_line(e.value)
    assert "huge.bag: damaged at byte" in msg and "more than the 256 MiB limit" in msg, msg
    assert_cli_error(*cli(capsys, p), "huge.bag: damaged at byte", "256 MiB limit")


def test_a_ros1_bag_whose_record_lengths_overrun_the_file_is_refused_without_reading_them(tmp_path):
    p = tmp_path / "overrun.bag"
    p.write_bytes(b"#ROSBAG V2.0\n" + struct.pack("<I", 0xFFFFFFF0) + b"op=\x05")
    with pytest.raises(McapDataError, match=r"overrun.bag: damaged at byte 13 of 21: record header of 4294967280 bytes"):
        open_depth_stream(p)
    p.write_bytes(b"#ROSBAG V2.0\n" + _ros1_record(b"", op=b"\x05")[:-4] + struct.pack("<I", 1 << 30))
    with pytest.raises(McapDataError, match=r"record data of 1073741824 bytes does not fit in the file"):
        open_depth_stream(p)

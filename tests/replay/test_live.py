"""The live Foxglove stream, seen by a real WebSocket client on 127.0.0.1.

The client speaks the Foxglove WebSocket protocol itself (``websockets``): it reads the server's
``advertise``, subscribes to the mask topic, and decodes every binary ``MessageData`` frame with
the protobuf schema the server advertised. Only loopback, bounded loops, bounded time.
"""

from __future__ import annotations

import base64
import json
import struct
import threading
import time

import numpy as np
import pytest
from replaygen import FakeSegmenter, write_ros2

from edge.errors import ConfigError
from edge.io.reader import open_depth_stream
from replay.writer import MASK_COLOURS

pytest.importorskip("foxglove")
ws_sync = pytest.importorskip("websockets.sync.client")

from replay.live import LiveServer, parse_address, stream_live  # noqa: E402

SUBPROTOCOLS = ["foxglove.sdk.v1", "foxglove.websocket.v1"]
TIMEOUT_S = 30.0


def collect(url: str, topics: list[str], want: int, timeout: float = TIMEOUT_S) -> dict[str, list]:
    """Subscribe to ``topics``; return decoded messages per topic once ``topics[0]`` has ``want``."""
    from mcap.records import Schema
    from mcap_protobuf.decoder import DecoderFactory

    got: dict[str, list] = {t: [] for t in topics}
    subs: dict[int, tuple[str, object]] = {}
    deadline = time.monotonic() + timeout
    with ws_sync.connect(url, subprotocols=SUBPROTOCOLS, open_timeout=10, max_size=None) as ws:
        while len(got[topics[0]]) < want:
            left = deadline - time.monotonic()
            if left <= 0:
                break
            try:
                msg = ws.recv(timeout=left)
            except TimeoutError:
                break
            if isinstance(msg, str):
                d = json.loads(msg)
                if d.get("op") != "advertise":
                    continue
                new = []
                for ch in d["channels"]:
                    if ch["topic"] in topics and ch["id"] not in {c for c in subs}:
                        assert ch["encoding"] == "protobuf" and ch.get("schemaEncoding", "protobuf") == "protobuf"
                        schema = Schema(id=1, name=ch["schemaName"], encoding="protobuf",
                                        data=base64.b64decode(ch["schema"]))
                        subs[ch["id"]] = (ch["topic"], DecoderFactory().decoder_for("protobuf", schema))
                        new.append({"id": ch["id"], "channelId": ch["id"]})
                if new:
                    ws.send(json.dumps({"op": "subscribe", "subscriptions": new}))
            elif msg[0] == 0x01:  # MessageData: u32 subscription id, u64 log time, payload
                sub_id, log_time = struct.unpack_from("<IQ", msg, 1)
                topic, decode = subs[sub_id]
                got[topic].append((log_time, decode(msg[13:])))
    return got


def test_parse_address():
    assert parse_address("8765") == ("127.0.0.1", 8765)
    assert parse_address("0.0.0.0:9000") == ("0.0.0.0", 9000)
    with pytest.raises(ConfigError, match=r"expected \[HOST:\]PORT"):
        parse_address("localhost:http")


def test_websocket_client_receives_live_masks_while_a_recording_replays(tmp_path):
    rec = write_ros2(tmp_path / "rec.mcap", n=40, invalid="nan")
    stream = open_depth_stream(rec.path)
    with LiveServer("127.0.0.1", 0) as srv:
        result: dict = {}

        def serve() -> None:
            try:
                # paced at 5x real time (20 fps recording -> 100 fps), after the client subscribed
                result["summary"] = stream_live(stream, FakeSegmenter(), server=srv, rate=5.0, wait_for_client=20)
            except Exception as exc:  # reported by the assertion below
                result["error"] = exc

        th = threading.Thread(target=serve, daemon=True)
        th.start()
        got = collect(f"ws://127.0.0.1:{srv.port}", ["/depthseg/mask", "/depthseg/camera_info"], want=10)
        th.join(timeout=TIMEOUT_S)
        assert not th.is_alive() and "error" not in result, result.get("error")
    masks = got["/depthseg/mask"]
    assert len(masks) >= 10
    for log_time, m in masks:
        assert (m.width, m.height, m.encoding, m.step) == (32, 24, "rgb8", 96)
        i = (log_time - rec_t0(rec)) // 50_000_000
        rgb = np.frombuffer(m.data, np.uint8).reshape(24, 32, 3)
        # decoded mask = the colours of the classes the segmenter gives for this very frame
        expected = FakeSegmenter().predict(rec.depth[i]).mask
        assert np.array_equal(rgb, MASK_COLOURS[expected])
        assert m.timestamp.seconds * 10**9 + m.timestamp.nanos == log_time
    assert got["/depthseg/camera_info"] and list(got["/depthseg/camera_info"][0][1].K)[0] > 0
    assert result["summary"].frames == 40


def rec_t0(rec) -> int:
    from replaygen import T0

    return T0


def test_python_api_takes_plain_arrays_and_a_taken_port_is_one_line(tmp_path):
    with LiveServer("127.0.0.1", 0, namespace="/robot1/seg") as srv:
        assert srv.topics["mask"] == "/robot1/seg/mask"
        with pytest.raises(ConfigError, match=f"cannot serve on 127.0.0.1:{srv.port}"):
            LiveServer("127.0.0.1", srv.port)
        depth = np.full((8, 8), 0.3, np.float32)
        depth[2:4, 2:4] = 0.25
        s = stream_live([depth, depth, depth], FakeSegmenter(), server=srv)
        assert s.frames == 3 and srv.published == 3
    with pytest.raises(ConfigError, match="`namespace` 'robot 1' is not a ROS namespace"):  # library: parameter names
        LiveServer("127.0.0.1", 0, namespace="robot 1")


def test_replay_cli_serve_and_one_line_errors(tmp_path, linear_onnx, capsys):
    from replay.cli import main

    rec = write_ros2(tmp_path / "rec.mcap", n=5)
    argv = [str(rec.path), "--model", str(linear_onnx), "--json"]
    assert main(argv + ["--serve", "127.0.0.1:0", "--no-wait", "--no-pace", "--out-namespace", "/r1/seg"]) == 0
    cap = capsys.readouterr()
    assert '"frames": 5' in cap.out and "ws://127.0.0.1:" in cap.err and "/r1/seg" in cap.err
    for bad, needle in ((["--serve", "host:port"], "--serve 'host:port': expected [HOST:]PORT"),
                        (["--out-namespace", "no slash"], "--out-namespace 'no slash' is not a ROS namespace")):
        assert main(argv + bad) == 2
        err = capsys.readouterr().err.strip()
        assert needle in err and len(err.splitlines()) == 1 and "Traceback" not in err

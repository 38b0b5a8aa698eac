"""Measure the live Foxglove stream: frames/s served and received by a WebSocket client.

    .venv/bin/python tools/bench_live.py REC.mcap [--model M.onnx] [--threads 2] [--repeat 3]

Starts `replay.live.LiveServer` on 127.0.0.1 (free port), connects a Foxglove-protocol client
(``websockets``) that subscribes to every topic and decodes the mask messages, waits for it to
subscribe, then replays the recording as fast as possible with the model (``--rate`` none).
Prints one JSON object: server frames/s (model + publishing, wall clock), the CPU time spent
publishing per frame (thread CPU, unaffected by other load), the whole process's CPU time per
frame (model on all its threads, decoding, publishing, the server and this client) and the
frames/s that leaves per CPU core, and how many mask messages the client received and decoded, at
what rate.
"""

from __future__ import annotations

import argparse
import base64
import json
import struct
import sys
import threading
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def client(url: str, stop: threading.Event, out: dict) -> None:
    from mcap.records import Schema
    from mcap_protobuf.decoder import DecoderFactory
    from websockets.sync.client import connect

    subs: dict[int, tuple[str, object]] = {}
    times: list[float] = []
    with connect(url, subprotocols=["foxglove.sdk.v1", "foxglove.websocket.v1"], max_size=None) as ws:
        while not stop.is_set():
            try:
                msg = ws.recv(timeout=0.5)
            except TimeoutError:
                continue
            if isinstance(msg, str):
                d = json.loads(msg)
                if d.get("op") == "advertise":
                    new = []
                    for ch in d["channels"]:
                        schema = Schema(id=1, name=ch["schemaName"], encoding="protobuf", data=base64.b64decode(ch["schema"]))
                        subs[ch["id"]] = (ch["topic"], DecoderFactory().decoder_for("protobuf", schema))
                        new.append({"id": ch["id"], "channelId": ch["id"]})
                    ws.send(json.dumps({"op": "subscribe", "subscriptions": new}))
            elif msg[0] == 0x01:
                sub_id, _ = struct.unpack_from("<IQ", msg, 1)
                topic, dec = subs[sub_id]
                out[topic] = out.get(topic, 0) + 1
                if topic.endswith("/mask"):
                    m = dec(msg[13:])
                    assert len(m.data) == m.height * m.step
                    times.append(time.perf_counter())
    out["mask_times"] = times


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("recording", type=Path)
    p.add_argument("--model", type=Path, default=None)
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--repeat", type=int, default=1, help="replay the recording this many times")
    args = p.parse_args(argv)

    from edge.infer import Segmenter
    from edge.io import open_depth_stream
    from replay.live import LiveServer, stream_live

    seg = Segmenter(args.model, threads=args.threads)
    stream = open_depth_stream(args.recording)
    publish_s = [0.0]
    with LiveServer("127.0.0.1", 0) as srv:
        stop = threading.Event()
        got: dict = {}
        th = threading.Thread(target=client, args=(srv.url, stop, got), daemon=True)
        th.start()
        if not srv.wait_for_client(30):
            print("no client subscribed within 30 s", file=sys.stderr)
            return 1
        time.sleep(0.5)  # let the client subscribe to every channel
        orig = srv.publish_result

        def timed(r) -> None:
            t0 = time.thread_time()  # CPU time of this thread: independent of other load on the machine
            orig(r)
            publish_s[0] += time.thread_time() - t0

        srv.publish_result = timed  # type: ignore[method-assign]
        frames, seconds = 0, 0.0
        lat = []
        cpu0 = time.process_time()
        for _ in range(args.repeat):
            s = stream_live(stream, seg, server=srv, wait_for_client=0)
            frames += s.frames
            seconds += s.seconds
            lat.append(s.latency.percentile(50))
        cpu = time.process_time() - cpu0  # model (all ORT threads), decoding, publishing, and the client
        time.sleep(1.0)  # let the last messages arrive
        stop.set()
        th.join(10)
    t = got.get("mask_times", [])
    rx_rate = (len(t) - 1) / (t[-1] - t[0]) if len(t) > 1 else None
    print(json.dumps({
        "frames": frames,
        "server_fps": round(frames / seconds, 1),
        "model_p50_ms": round(sorted(lat)[len(lat) // 2], 2),
        "publish_cpu_ms_per_frame": round(1e3 * publish_s[0] / frames, 3),
        "process_cpu_ms_per_frame": round(1e3 * cpu / frames, 2),
        "fps_per_cpu_core": round(frames / cpu, 1),
        "client_masks_decoded": len(t),
        "client_mask_rate_hz": None if rx_rate is None else round(rx_rate, 1),
        "client_messages": {k: v for k, v in got.items() if k != "mask_times"},
    }, sort_keys=True))
    return 0


if __name__ == "__main__":
    sys.exit(main())

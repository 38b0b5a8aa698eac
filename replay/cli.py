"""``depthseg-replay``: run the ONNX model over a recorded or simulated MCAP, as the robot would.

Thin wrapper: `edge.io.reader.open_depth_stream` finds the topics, `edge.infer.Segmenter` runs the
model, `replay.replay.replay` loops, scores and writes. Informational lines (which topic was
chosen, camera intrinsics) go to stderr; the summary (or ``--json``) goes to stdout. Edge path:
no torch import here.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from edge.cliutil import add_min_height_arg, add_version, print_json, progress, run
from edge.errors import ConfigError, ModelError

PROG = "depthseg-replay"

DESCRIPTION = """\
Replay depth frames from a recording (MCAP, ROS 1 .bag, ROS 2 .db3 or bag directory) through
the segmentation model and report what it does: frames/s, latency percentiles, the share of unknown (invalid-depth) pixels and, when the
recording has labels, IoU, precision, recall and pixel accuracy over valid pixels.

Reads sensor_msgs/Image (32FC1 metres with 0 or NaN invalid; 16UC1 millimetres),
sensor_msgs/CompressedImage compressedDepth (png), foxglove RawImage (protobuf or JSON) and
depthseg-sim recordings; ROS 1 and ROS 2 bags need the 'ros' extra (rosbags). The depth topic is found
automatically (depth encodings and names); --topic overrides it. CameraInfo is used when present.
Frames of any size work: they are zero-padded to multiples of 32 for the network and cropped back.
"""

EPILOG = """\
output (--out): the input's messages copied through, plus /depthseg/mask (rgb8: table dark blue,
objects orange, unknown magenta), /depthseg/mask_raw (mono8: 0 background, 1 object, 255 unknown)
and /depthseg/overlay (rgb8: grey depth, orange objects, magenta unknown), on the depth frames'
timestamps; open it in Foxglove. --out-namespace changes the /depthseg prefix. A recording that
already has one of these topics (e.g. a replay output replayed again) is refused before any work,
naming a free namespace to pass to --out-namespace: one topic never gets two channels. --out
must be a new or regular file that is not the recording (nor inside a bag directory).
pacing (--rate): frames follow the recording's log times, but a jump of its clock longer than
1 s (a paused recorder) is skipped, said once on stderr and counted in the summary.
limits: frames larger than 4096x4096 (--max-frame) are refused from their header, before any
pixel is decoded; FIFOs and devices are refused as input (copy the stream to a file first).
A 32FC1 depth image whose median is beyond 10 m gets one warning that it looks like
millimetres; --depth-scale 0.001 reads it as metres.
live (--serve [HOST:]PORT, needs foxglove-sdk): a Foxglove WebSocket server; in Foxglove choose
Open connection -> Foxglove WebSocket -> ws://HOST:PORT. It streams <ns>/depth, <ns>/mask,
<ns>/overlay and <ns>/camera_info while the recording replays (at its own rate unless --rate);
replay starts when the first client subscribes (--no-wait: at once). HOST defaults to 127.0.0.1
(this machine only); 0.0.0.0 serves the network.
A damaged recording is replayed up to the damage; the output is still written, then the error
is reported and the exit code is 2.

examples:
  depthseg-replay rec.mcap
  depthseg-replay rec.mcap --out rec_seg.mcap --rate 1.0
  depthseg-replay rec.mcap --topic /camera/depth/image_raw --labels-topic "" --json
  depthseg-replay robot.bag --serve 8765              # then connect Foxglove to ws://127.0.0.1:8765
  depthseg-replay rosbag2_dir/ --serve 0.0.0.0:8765 --no-pace --out-namespace /robot1/seg
"""


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog=PROG, description=DESCRIPTION, epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    add_version(p, PROG)
    p.add_argument("recording", type=Path,
                   help="an .mcap file (ROS 2, Foxglove or depthseg-sim), a ROS 1 .bag, a ROS 2 .db3 or a ROS 2 bag "
                   "directory (metadata.yaml)")
    p.add_argument("--model", type=Path, default=None,
                   help="exported .onnx model (default: the shipped edge/models/default.onnx)")
    p.add_argument("--topic", default=None, help="depth image topic (default: detected; the error lists candidates)")
    p.add_argument("--labels-topic", default=None,
                   help="mono8 label topic, nonzero = object (default: a '*labels*' image topic if there is one; "
                   "'' disables scoring)")
    p.add_argument("--out", type=Path, default=None, help="write an MCAP with the input plus mask and overlay topics")
    p.add_argument("--rate", type=float, default=None,
                   help="pace playback to the recording's timestamps (1.0 = real time, 0.001 to 1000; default: as "
                   "fast as possible, or 1.0 with --serve); clock jumps over 1 s are skipped")
    p.add_argument("--depth-scale", type=float, default=1.0, metavar="S",
                   help="multiply decoded depth by S (0.001: millimetres stored as 32FC1; default 1)")
    p.add_argument("--max-frame", type=_size, default=(4096, 4096), metavar="WxH",
                   help="refuse depth frames larger than this (default 4096x4096)")
    p.add_argument("--serve", metavar="[HOST:]PORT", default=None,
                   help="stream depth, mask, overlay and camera info live to Foxglove (WebSocket) while replaying")
    p.add_argument("--no-wait", action="store_true", help="with --serve: start replaying without waiting for a client")
    p.add_argument("--no-pace", action="store_true", help="with --serve: replay as fast as possible instead of at 1.0")
    p.add_argument("--out-namespace", default="/depthseg",
                   help="topic prefix of the mask, mask_raw and overlay topics of --out and --serve (default /depthseg)")
    p.add_argument("--threshold", type=float, default=None,
                   help="object probability threshold (default: the one stored in the model)")
    p.add_argument("--min-object-px", type=int, default=None, metavar="PX",
                   help="object specks (8-connected) under PX pixels become background (default: the model's rule; "
                        "0 keeps every object pixel)")
    add_min_height_arg(p)
    p.add_argument("--threads", type=int, default=2, help="onnxruntime intra-op threads (default 2)")
    p.add_argument("--json", action="store_true",
                   help="print one JSON object (frames, fps, p50_ms, ... and iou, precision, recall, "
                   "pixel_accuracy with labels)")
    return p


def _size(text: str) -> tuple[int, int]:
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected WIDTHxHEIGHT such as 4096x4096, got '{text}'") from None
    if w < 1 or h < 1:
        raise argparse.ArgumentTypeError(f"width and height must be >= 1, got '{text}'")
    return w, h


def _note(msg: str) -> None:
    print(f"{PROG}: {msg}", file=sys.stderr)


def _report(summary, as_json: bool) -> None:
    if as_json:
        print_json(summary.to_dict())
    else:
        for line in summary.lines():
            print(line)


def _body(args: argparse.Namespace) -> int:
    from edge.cliutil import cli_message, flag_names
    from edge.infer import Segmenter
    from edge.io.paths import check_input_file, check_outputs
    from edge.io.reader import open_depth_stream
    from replay.replay import ReplayDataError, check_rate, replay
    from replay.writer import check_namespace, check_output_topics

    if args.threads < 1:
        raise ConfigError(f"--threads must be >= 1, got {args.threads}")
    if args.recording.exists():
        check_input_file(args.recording, "recording", allow_dir=True)
    if args.model is not None and args.model.exists():  # (a missing model is the Segmenter's one line)
        check_input_file(args.model, "model")
    if args.model is not None and args.model.suffix.lower() in (".pt", ".pth"):
        raise ModelError(
            f"{args.model}: replay runs exported ONNX models; export the checkpoint with depthseg-export first"
        )
    check_outputs({"out": args.out}, {"recording": args.recording, "model": args.model})
    check_namespace(args.out_namespace)
    if args.no_pace and args.rate is not None:
        raise ConfigError("--no-pace and --rate contradict each other; give one")
    check_rate(args.rate)
    flags = flag_names(build_parser())
    rate = args.rate
    if rate is None and args.serve is not None and not args.no_pace:
        rate = 1.0
    address = None
    if args.serve is not None:
        from replay.live import parse_address

        address = parse_address(args.serve)
    stream = open_depth_stream(
        args.recording, args.topic, args.labels_topic, max_frame=args.max_frame, depth_scale=args.depth_scale,
        on_warning=lambda m: _note("warning: " + cli_message(m, flags)),
    )
    if args.out is not None:
        check_output_topics(stream.topics, args.out_namespace)
    seg = Segmenter(args.model, threads=args.threads, threshold=args.threshold, min_object_px=args.min_object_px,
                    min_height_m=args.min_height_m)
    _note(f"depth topic {stream.depth_topic} ({stream.depth_reason})")
    _note(f"labels: {stream.labels_topic or 'none (no scores)'}")
    s = seg.meta.sensor
    if stream.camera_info:
        ci = stream.camera_info
        _note(
            f"camera_info {stream.info_topic}: {ci['width']}x{ci['height']} fx {ci['fx']:.1f} fy {ci['fy']:.1f} "
            f"(model trained for {s.width}x{s.height} fx {s.fx:.1f} fy {s.fy:.1f})"
        )
    sizes_noted: set[tuple[int, int]] = set()
    live = None
    if address is not None:
        from replay.live import LiveServer

        live = LiveServer(*address, namespace=args.out_namespace)
        _note(f"live: Foxglove -> Open connection -> Foxglove WebSocket -> {live.url}  (topics {args.out_namespace}/...)")
        if not args.no_wait:
            _note("waiting for a Foxglove client to subscribe (Ctrl-C to stop)")
            live.wait_for_client(None)
    bar = progress(total=stream.frame_count, desc="replay", unit="frame")

    def on_frame(r) -> None:
        hw = r.mask.shape
        if hw != (s.height, s.width) and hw not in sizes_noted:
            sizes_noted.add(hw)
            bar.write(
                f"{PROG}: frames are {hw[1]}x{hw[0]}, the model was trained on {s.width}x{s.height}; "
                "padded to multiples of 32, scores may differ", file=sys.stderr,
            )
        if live is not None:
            live.publish_result(r)
        bar.update(1)

    try:
        summary = replay(stream, seg, out=args.out, rate=rate, on_frame=on_frame, out_namespace=args.out_namespace,
                         on_note=lambda m: bar.write(f"{PROG}: {m}", file=sys.stderr))
    except ReplayDataError as exc:
        bar.close()
        _report(exc.summary, args.json)
        raise
    finally:
        bar.close()
        if live is not None:
            live.close()
    _report(summary, args.json)
    return 0


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    aliases = {
        "depth_topic": "--topic", "namespace": "--out-namespace", "address": "--serve", "port": "--serve [HOST:]PORT",
        "recording": "recording",  # the positional argument
    }
    return run(PROG, lambda: _body(args), parser, aliases=aliases)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())

"""Live segmentation in Foxglove: a WebSocket server (``foxglove-sdk``) fed by any frame loop.

Why a server of our own topics and not a re-publish of the input: a robot user wants to watch
what the model does *now*, next to the depth it saw, in the viewer the MCAP ecosystem uses.
Foxglove connects to ``ws://HOST:PORT`` (Open connection -> Foxglove WebSocket) and shows, under
a namespace (``/depthseg`` by default):

- ``<ns>/depth``        foxglove.RawImage 32FC1, metres (the frame as the model got it);
- ``<ns>/mask``         foxglove.RawImage rgb8: table dark blue, objects orange, unknown magenta
  (`replay.writer.MASK_COLOURS`, the same picture as the ``--out`` file's mask topic);
- ``<ns>/overlay``      foxglove.RawImage rgb8: grey depth, orange objects, magenta unknown;
- ``<ns>/camera_info``  foxglove.CameraCalibration, when the frame carries intrinsics.

Three ways in, from the most to the least packaged:

- ``depthseg-replay REC --serve 8765``: replays a recording (any format the reader takes) at its
  own rate (``--rate``) into the server;
- `stream_live` (any iterable of depth arrays or `edge.io.Frame`): segments and publishes,
  optionally paced; this is the loop a camera driver or a ROS 2 node callback runs;
- `LiveServer.publish` for one frame and its mask, when the caller runs the model itself.

foxglove-sdk is an optional dependency (``pip install 'depthseg[ros]'``); the edge path does not
import it. Publishing costs well under a millisecond a frame (BENCHMARKS.md), so the server
keeps up with the sensor's 45 fps.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Iterable
from typing import Any

import numpy as np

from edge.errors import ConfigError, DepthsegError
from edge.io import Frame
from replay.writer import DEFAULT_NAMESPACE, check_namespace, mask_rgb, overlay_rgb

__all__ = ["LiveServer", "stream_live", "parse_address", "live_topics", "INSTALL_HINT"]

INSTALL_HINT = "pip install 'depthseg[ros]' (or: pip install foxglove-sdk)"


def parse_address(address: str) -> tuple[str, int]:
    """``"8765"`` -> ("127.0.0.1", 8765); ``"0.0.0.0:8765"`` -> ("0.0.0.0", 8765)."""
    host, _, port = str(address).rpartition(":")
    host = host.strip("[]") or "127.0.0.1"
    try:
        p = int(port)
    except ValueError:
        raise ConfigError(f"`address` '{address}': expected [HOST:]PORT such as 8765 or 0.0.0.0:8765") from None
    if not 0 <= p <= 65535:
        raise ConfigError(f"`address` '{address}': port must be 0-65535 (0 = any free port)")
    return host, p


def live_topics(namespace: str = DEFAULT_NAMESPACE) -> dict[str, str]:
    ns = check_namespace(namespace)
    return {k: f"{ns}/{k}" for k in ("depth", "mask", "overlay", "camera_info")}


def _timestamp(stamp_ns: int):
    from foxglove.messages import Timestamp

    return Timestamp(int(stamp_ns // 1_000_000_000), int(stamp_ns % 1_000_000_000))


class LiveServer:
    """A Foxglove WebSocket server publishing depth, mask, overlay and camera calibration.

    Args:
        host: interface to bind; the default ``127.0.0.1`` is reachable from this machine only,
            ``0.0.0.0`` from the network (the robot's viewer on another computer).
        port: TCP port; 0 picks a free one (read it back from ``port``).
        namespace: topic prefix, ``/depthseg`` by default.
        overlay: also publish the overlay picture.

    Use as a context manager, or call `close`. Raises `ConfigError` when the port is taken and
    `DepthsegError` when foxglove-sdk is not installed.
    """

    def __init__(
        self, host: str = "127.0.0.1", port: int = 8765, *, namespace: str = DEFAULT_NAMESPACE, overlay: bool = True
    ) -> None:
        try:
            import foxglove
            from foxglove.channels import CameraCalibrationChannel, RawImageChannel
        except ImportError:
            raise DepthsegError(f"the live stream needs foxglove-sdk: {INSTALL_HINT}") from None
        self.topics = live_topics(namespace)
        self._subscribed = threading.Event()
        self.subscriptions = 0
        outer = self

        class _Listener(foxglove.ServerListener):
            def on_subscribe(self, client, channel) -> None:  # noqa: ARG002 (foxglove's signature)
                outer.subscriptions += 1
                outer._subscribed.set()

            def on_unsubscribe(self, client, channel) -> None:  # noqa: ARG002
                outer.subscriptions = max(0, outer.subscriptions - 1)

        self._ctx = foxglove.Context()
        try:
            self._server = foxglove.start_server(
                name="depthseg", host=host, port=int(port), context=self._ctx, server_listener=_Listener()
            )
        except Exception as exc:  # the SDK raises RuntimeError with the OS's text for a taken port
            raise ConfigError(
                f"cannot serve on {host}:{port} ({' '.join(str(exc).split())[:160]}); choose another `port` "
                "(0 picks a free one)"
            ) from None
        self.host = host
        self.port = int(self._server.port)
        t = self.topics
        self._depth = RawImageChannel(t["depth"], context=self._ctx)
        self._mask = RawImageChannel(t["mask"], context=self._ctx)
        self._overlay = RawImageChannel(t["overlay"], context=self._ctx) if overlay else None
        self._info = CameraCalibrationChannel(t["camera_info"], context=self._ctx)
        self.published = 0
        self._closed = False

    @property
    def url(self) -> str:
        return f"ws://{self.host}:{self.port}"

    def wait_for_client(self, timeout: float | None = None) -> bool:
        """Block until a client subscribes to any topic (True) or ``timeout`` seconds pass (False)."""
        return self._subscribed.wait(timeout)

    def publish(
        self,
        depth: np.ndarray,
        mask: np.ndarray,
        stamp_ns: int | None = None,
        *,
        frame_id: str = "",
        info: dict[str, Any] | None = None,
    ) -> None:
        """Publish one frame: depth (metres), its mask (0 background, 1 object, 255 unknown), info."""
        from foxglove.messages import CameraCalibration, RawImage

        t = time.time_ns() if stamp_ns is None else int(stamp_ns)
        ts = _timestamp(t)
        d = np.ascontiguousarray(depth, dtype=np.float32)
        h, w = d.shape
        self._depth.log(
            RawImage(timestamp=ts, frame_id=frame_id, width=w, height=h, encoding="32FC1", step=w * 4, data=d.tobytes()),
            log_time=t,
        )
        m = np.asarray(mask, dtype=np.uint8)
        self._mask.log(
            RawImage(timestamp=ts, frame_id=frame_id, width=w, height=h, encoding="rgb8", step=w * 3,
                     data=mask_rgb(m).tobytes()),
            log_time=t,
        )
        if self._overlay is not None:
            self._overlay.log(
                RawImage(timestamp=ts, frame_id=frame_id, width=w, height=h, encoding="rgb8", step=w * 3,
                         data=overlay_rgb(d, m).tobytes()),
                log_time=t,
            )
        if info:
            fx, fy, cx, cy = (float(info[k]) for k in ("fx", "fy", "cx", "cy"))
            self._info.log(
                CameraCalibration(
                    timestamp=ts, frame_id=info.get("frame_id") or frame_id, width=int(info.get("width") or w),
                    height=int(info.get("height") or h), distortion_model=info.get("distortion_model") or "plumb_bob",
                    D=[float(v) for v in info.get("d") or []], K=[fx, 0.0, cx, 0.0, fy, cy, 0.0, 0.0, 1.0],
                    R=[1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
                    P=[fx, 0.0, cx, 0.0, 0.0, fy, cy, 0.0, 0.0, 0.0, 1.0, 0.0],
                ),
                log_time=t,
            )
        self.published += 1

    def publish_result(self, result) -> None:
        """`replay.replay.replay`'s ``on_frame`` callback: publish a `FrameResult`."""
        fr = result.frame
        stamp = int(fr.extra.get("header_stamp_ns") or fr.stamp_ns) if fr.extra else int(fr.stamp_ns)
        self.publish(fr.depth, result.mask, stamp, frame_id=str(fr.extra.get("frame_id", "")), info=fr.info)

    def close(self) -> None:
        if not self._closed:
            self._closed = True
            self._server.stop()

    def __enter__(self) -> LiveServer:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def _frames(source: Iterable[Any]) -> Iterable[Frame]:
    for item in source:
        if isinstance(item, Frame):
            yield item
        else:
            yield Frame(depth=np.asarray(item, dtype=np.float32), stamp_ns=time.time_ns())


def stream_live(
    frames: Iterable[Any],
    segmenter=None,
    *,
    server: LiveServer | None = None,
    host: str = "127.0.0.1",
    port: int = 8765,
    namespace: str = DEFAULT_NAMESPACE,
    rate: float | None = None,
    wait_for_client: float | None = 0.0,
    on_frame: Callable[[Any], None] | None = None,
):
    """Segment every frame of ``frames`` and publish it live; returns the `ReplaySummary`.

    Args:
        frames: depth arrays (H x W metres; 0, NaN, inf, negative = invalid) or `Frame` objects,
            e.g. a camera driver's generator or a `edge.io.DepthStream`.
        segmenter: an `edge.infer.Segmenter` (default: the shipped model).
        server: a running `LiveServer`; else one is started on ``host:port`` and closed at the end.
        rate: pace to the frames' stamps (1.0 = real time); None = as they come.
        wait_for_client: seconds to wait for a Foxglove client before the first frame
            (None = forever, 0 = do not wait).
        on_frame: also called with every `replay.replay.FrameResult`.
    """
    from replay.replay import replay

    if segmenter is None:
        from edge.infer import Segmenter

        segmenter = Segmenter()
    own = server is None
    srv = server or LiveServer(host, port, namespace=namespace)
    try:
        if wait_for_client is None or wait_for_client > 0:
            srv.wait_for_client(wait_for_client)

        def cb(r) -> None:
            srv.publish_result(r)
            if on_frame is not None:
                on_frame(r)

        return replay(_frames(frames), segmenter, rate=rate, on_frame=cb)
    finally:
        if own:
            srv.close()

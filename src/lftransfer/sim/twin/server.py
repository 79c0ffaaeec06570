"""The twin's network face: camera streams that OpenCV opens by URL, the cameras' control API, the operator endpoint.

One HTTP server (standard library, a thread per connection) on the twin's port:

- ``GET /lf``, ``GET /view``: the camera's stream, as IP and streaming cameras serve one: a NUT container of
  FFV1 video (FFmpeg's lossless intra-frame codec), encoded per client with PyAV, each frame GRAY16LE of the
  three colour planes stacked (3 H x W). Why: OpenCV's ``VideoCapture`` (FFmpeg back-end) returns 16-bit frames
  only for GRAY16LE (its 16-bit colour formats arrive as 8 bits), and FFV1 keeps every bit of the 12-bit LF
  camera and the 16-bit view camera; a lossy codec (MJPEG, H.264) would add its own error to the light field.
  Each frame's presentation time is its camera timestamp (:mod:`.cameras`), in microseconds from the first frame
  the client was sent.
- ``GET /lf/control``, ``POST /lf/control``: ``{"exposure": value}``, the LF camera's exposure (exposure
  bracketing during calibration), in the units of the rig file's ``lf_camera.exposure``.
- ``POST /operator``: a set-up (:mod:`lftransfer.rig.hardware.operator`'s JSON); answered once the world shows it.
- ``GET /status``: frames published, dropped and rendered, the epoch, the streams' clients (JSON).
"""

from __future__ import annotations

import io
import json
import logging
import queue
import threading
import time
from fractions import Fraction
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from typing import Callable

from lftransfer.rig.requests import setup_from_json
from lftransfer.sim.twin.cameras import TwinCamera

__all__ = ["TwinServer"]

_log = logging.getLogger(__name__)

_PTS_UNIT = Fraction(1, 1_000_000)      # the streams' time base: frame timestamps in microseconds


class _SocketWriter(io.RawIOBase):
    """A write-only file over the client's socket, for PyAV's muxer."""

    def __init__(self, wfile) -> None:  # noqa: ANN001
        super().__init__()
        self._w = wfile

    def writable(self) -> bool:
        return True

    def write(self, data) -> int:  # noqa: ANN001
        self._w.write(data)
        self._w.flush()
        return len(data)


def _stream(handler: BaseHTTPRequestHandler, camera: TwinCamera) -> None:
    import av

    q = camera.subscribe()
    if q is None:
        handler.send_error(503, f"the {camera.name} camera's stream is stopped")
        return
    try:
        first = q.get(timeout=60.0)
    except queue.Empty:
        camera.unsubscribe(q)
        handler.send_error(504, f"the {camera.name} camera sent no frame")
        return
    if first is None:
        camera.unsubscribe(q)
        handler.send_error(503, f"the {camera.name} camera's stream is stopped")
        return
    handler.send_response(200)
    handler.send_header("Content-Type", "video/x-nut")
    handler.send_header("Cache-Control", "no-store")
    handler.end_headers()
    container = None
    try:
        container = av.open(_SocketWriter(handler.wfile), mode="w", format="nut",
                           container_options={"flush_packets": "1"})
        stream = container.add_stream("ffv1", rate=Fraction(camera.timing.fps).limit_denominator(1000))
        stream.height, stream.width = first[2].shape
        stream.pix_fmt = "gray16le"
        stream.codec_context.time_base = stream.time_base = _PTS_UNIT
        item, origin, pts = first, first[1], -1
        while item is not None:
            tick, stamp, frame = item
            vf = av.VideoFrame.from_ndarray(frame, format="gray16le")
            # the camera's timestamp (strictly increasing, as a container needs: jitter may reorder two stamps)
            pts = max(pts + 1, int(round((stamp - origin) / _PTS_UNIT)))
            vf.pts, vf.time_base = pts, _PTS_UNIT
            for packet in stream.encode(vf):
                container.mux(packet)
            camera.note_sent(time.monotonic() - tick)
            item = q.get()
    except (BrokenPipeError, ConnectionResetError, OSError) as exc:
        _log.info("twin %s stream: client gone (%s)", camera.name, type(exc).__name__)
    finally:
        camera.unsubscribe(q)
        handler.close_connection = True
        if container is not None:
            try:
                container.close()
            except Exception:  # noqa: BLE001  (the socket is gone)
                pass


class TwinServer:
    """The HTTP server of a twin.

    Args:
        cameras: {"lf": camera, "view": camera}.
        exposure: {"lf": (get, set)}: the cameras whose exposure can be set over the network.
        arrange: {"operator": apply, ...}: each operator endpoint's path (``operator`` for the first light field
            interface, ``operator/NAME`` for the others) and what applies a set-up request there (blocks until
            done).
        status: returns the twin's status (a JSON-able dict).
        host, port: where to listen (port 0: any free one).
    """

    def __init__(self, cameras: dict[str, TwinCamera],
                 exposure: dict[str, tuple[Callable[[], float], Callable[[float], float]]],
                 arrange: dict[str, Callable[[object], None]], status: Callable[[], dict], host: str = "127.0.0.1",
                 port: int = 0) -> None:

        class Handler(BaseHTTPRequestHandler):
            protocol_version = "HTTP/1.0"

            def log_message(self, fmt, *args):  # noqa: ANN001
                _log.debug("twin http: " + fmt, *args)

            def _json(self, code: int, data: dict) -> None:
                body = json.dumps(data).encode()
                self.send_response(code)
                self.send_header("Content-Type", "application/json")
                self.send_header("Content-Length", str(len(body)))
                self.end_headers()
                self.wfile.write(body)

            def _body(self) -> dict:
                n = int(self.headers.get("Content-Length") or 0)
                return json.loads(self.rfile.read(n).decode() or "{}") if n else {}

            def do_GET(self) -> None:  # noqa: N802
                path = self.path.split("?")[0].rstrip("/")
                name = path.lstrip("/")
                if name in cameras:
                    _stream(self, cameras[name])
                elif name.endswith("/control") and name[:-8] in exposure:
                    self._json(200, {"exposure": exposure[name[:-8]][0]()})
                elif name == "status":
                    self._json(200, status())
                else:
                    served = [*cameras, *(f"{c}/control" for c in exposure), *arrange, "status"]
                    self._json(404, {"error": f"no {path}; the twin serves " + ", ".join(f"/{x}" for x in served)})

            def do_POST(self) -> None:  # noqa: N802
                name = self.path.split("?")[0].strip("/")
                try:
                    body = self._body()
                except (ValueError, UnicodeDecodeError) as exc:
                    self._json(400, {"done": False, "error": f"not JSON: {exc}"})
                    return
                if name.endswith("/control") and name[:-8] in exposure:
                    value = body.get("exposure")
                    if not isinstance(value, (int, float)) or not value > 0:
                        self._json(400, {"error": f"expected {{\"exposure\": a positive number}}, got {body}"})
                        return
                    self._json(200, {"exposure": exposure[name[:-8]][1](float(value))})
                elif name in arrange:
                    try:
                        request = setup_from_json(body.get("setup") or {})
                    except (ValueError, TypeError) as exc:
                        self._json(400, {"done": False, "error": str(exc)})
                        return
                    try:
                        arrange[name](request)
                    except Exception as exc:  # noqa: BLE001  (told to the rig)
                        self._json(500, {"done": False, "error": f"{type(exc).__name__}: {exc}"})
                        return
                    self._json(200, {"done": True})
                else:
                    self._json(404, {"error": f"no {self.path}"})

        self._httpd = ThreadingHTTPServer((host, port), Handler)
        self._httpd.daemon_threads = True
        self.host, self.port = self._httpd.server_address[:2]
        self._thread = threading.Thread(target=self._httpd.serve_forever, name="twin-http", daemon=True)

    @property
    def url(self) -> str:
        return f"http://{self.host}:{self.port}"

    def start(self) -> None:
        self._thread.start()

    def close(self) -> None:
        self._httpd.shutdown()
        self._httpd.server_close()

"""Network stream cameras: :class:`StreamCamera`, a stream at a URL read by OpenCV's FFmpeg back-end on a reader
thread that notes every frame's arrival (the device twin's cameras and IP cameras).

It is a :class:`~lftransfer.rig.hardware.camera.Camera` (bounded waits, code conversion, exposure scale);
:func:`~lftransfer.rig.hardware.cameras.open_camera` opens one for a rig file's stream URL source, and
:mod:`.camera` re-exports it.
"""

from __future__ import annotations

import logging
import math
import os
import threading
import time
from typing import Any, Callable

import numpy as np

from lftransfer.rig.base import RigError
from lftransfer.rig.hardware.camera import Camera
from lftransfer.rig.hardware.config import CameraConfig

__all__ = ["StreamCamera", "StreamClock"]

_log = logging.getLogger(__name__)

_STREAM_OPEN = threading.Lock()
_FFMPEG_OPTIONS = "OPENCV_FFMPEG_CAPTURE_OPTIONS"


class StreamClock:
    """Carries a stream's frame timestamps to this machine's monotonic clock.

    A frame stamped ``pts`` seconds (the stream's own clock) that arrives at monotonic time ``a`` was taken no later
    than ``a``; the smallest ``a - pts`` seen is the offset between the clocks plus the quickest transport, so
    ``pts + offset`` is when the frame would have arrived with nothing in its way. A frame that waited (in a
    buffer, behind a busy reader) keeps its early date. Clock drift between the camera and this machine is taken
    as negligible over a connection (1 ppm is 3.6 ms an hour). :meth:`reset` on a new connection (its stamps
    start again)."""

    def __init__(self) -> None:
        self.reset()

    def reset(self) -> None:
        self._offset = math.inf
        self._last_pts = -math.inf
        self._last_date = -math.inf
        self.unusable = False

    def date(self, pts_s: float, arrival: float) -> float:
        """The monotonic time of a frame stamped ``pts_s`` that arrived at ``arrival``; the arrival itself once
        the stream's stamps stop increasing (a stream without timestamps: :attr:`unusable`)."""
        if self.unusable or not pts_s > self._last_pts:
            self.unusable = True
            return arrival
        self._last_pts = pts_s
        self._offset = min(self._offset, arrival - pts_s)
        # dates never go back (a smaller offset found later would move a frame before the one handed out last)
        self._last_date = max(pts_s + self._offset, self._last_date + 1e-6)
        return self._last_date


class StreamCamera(Camera):
    """A network camera: a stream at a URL (``http://``, ``tcp://``, ``rtsp://``, ...) read by OpenCV's FFmpeg back-end.

    A reader thread takes every frame as it arrives and dates it (a stream, unlike a V4L2 driver, buffers whatever
    is not read, so frames must be drained as they come): by its arrival, or with ``timestamps = "stream"`` by
    the frame's own timestamp (:class:`StreamClock`). :meth:`read_frame` hands out the next
    frame that arrived after the last one handed out and after :meth:`mark_change`'s time: stale frames are skipped,
    never averaged. A stream that ends or stalls is reconnected in the background; a capture waiting for a frame
    gives up after ``timeout_s`` with a :class:`~lftransfer.rig.base.RigError` naming the camera, the step and why
    the stream is down.

    Frames of more than 8 bits are read without OpenCV's BGR conversion (``CAP_PROP_CONVERT_RGB`` off: FFmpeg's
    GRAY16LE arrives as 16-bit); ``planar`` cameras send colour as three stacked monochrome planes. The exposure is
    set through the camera's control URL (``control``), where it has one.

    Args:
        config: the camera's table of the rig file (a stream URL source).
        role: how messages name it.
        capture_factory: ``(url, api_preference, params) -> capture`` (tests), or None for ``cv2.VideoCapture``.
    """

    continuous = True
    KEEP = 64                      # frames kept for a slow reader

    def __init__(self, config: CameraConfig, role: str = "camera",
                 capture_factory: Callable[[int | str, int, list[int]], Any] | None = None) -> None:
        if config.kind != "stream":
            raise ValueError(f"{role} ({config.source}): StreamCamera needs a stream URL source")
        super().__init__(config, role)
        import collections

        self._factory = capture_factory
        self._cond = threading.Condition()
        self._frames: collections.deque = collections.deque(maxlen=self.KEEP)
        self._last_t = -math.inf
        self._not_before = -math.inf
        self._down: str | None = None          # why the stream is down, while it is
        self._stop = threading.Event()
        self._reader: threading.Thread | None = None
        self._clock = StreamClock() if config.timestamps == "stream" else None
        self.arrived = 0

    def _connect(self) -> Any:
        import cv2

        c = self.config
        ms = int(round(c.timeout_s * 1000))
        # one decoding thread: FFmpeg's frame threads hold a frame back per extra thread (a frame of latency each)
        params = [cv2.CAP_PROP_OPEN_TIMEOUT_MSEC, ms, cv2.CAP_PROP_READ_TIMEOUT_MSEC, ms, cv2.CAP_PROP_N_THREADS, 1]
        raw = c.bits > 8 or c.planar
        if raw:
            params += [cv2.CAP_PROP_CONVERT_RGB, 0]
        with _STREAM_OPEN:
            # FFmpeg probes a stream for seconds of frames before it opens (analyzeduration, 5 s at most): a
            # camera's stream holds one video stream whose first frame says all, so it is not probed (unless the
            # user's own OPENCV_FFMPEG_CAPTURE_OPTIONS say otherwise); OpenCV reads the variable at each open
            own = _FFMPEG_OPTIONS not in os.environ
            if own:
                os.environ[_FFMPEG_OPTIONS] = "analyzeduration;0|probesize;32"
            try:
                cap = (self._factory or cv2.VideoCapture)(c.source, cv2.CAP_FFMPEG, params)
            finally:
                if own:
                    os.environ.pop(_FFMPEG_OPTIONS, None)
        if cap is None or not cap.isOpened():
            if cap is not None:
                cap.release()
            raise RigError(f"{self.label}: cannot open the camera: no stream at this URL (is the camera, or the "
                           "twin, running?)")
        return cap

    def open(self) -> "Camera":
        """Connect (FFmpeg's own time-outs fire first: the worker waits a little longer, so it is not left stuck
        inside FFmpeg) and start the reader thread."""
        self._call(self._open, step="opening the camera", doing="opening the stream",
                   timeout=self.config.timeout_s + 2.0)
        _log.info("%s: open", self.label)
        return self

    def _open(self) -> None:
        cap = self._connect()
        self._base_exposure = self._get_exposure()
        if self.config.exposure is not None and self.config.control is not None:
            got = self._set_exposure(self.config.exposure)
            if got is not None:
                self._base_exposure = got
        self._reader = threading.Thread(target=self._read_loop, args=(cap,), name=f"lft-{self.role}-reader",
                                        daemon=True)
        self._reader.start()

    def _read_loop(self, cap: Any) -> None:
        import cv2

        while not self._stop.is_set():
            if cap is None:
                try:
                    cap = self._connect()
                except Exception as exc:  # noqa: BLE001  (down: try again)
                    with self._cond:
                        self._down = str(exc).split(": ", 1)[-1]
                    self._stop.wait(0.5)
                    continue
            ok, frame = cap.read()
            t = time.monotonic()
            if not ok or frame is None:
                cap.release()
                cap = None
                if self._clock is not None:
                    self._clock.reset()
                with self._cond:
                    self._down = f"the stream stopped after {self.arrived} frames"
                    self._cond.notify_all()
                continue
            if self._clock is not None:
                was = self._clock.unusable
                t = self._clock.date(float(cap.get(cv2.CAP_PROP_POS_MSEC)) / 1000.0, t)
                if self._clock.unusable and not was:
                    _log.warning("%s: the stream's frame timestamps do not increase; frames are dated by their "
                                 "arrival (timestamps = \"arrival\" in the rig file says so)", self.label)
            if frame.ndim == 3 and frame.shape[2] == 3 and not (self.config.bits > 8 or self.config.planar):
                frame = cv2.cvtColor(frame, cv2.COLOR_BGR2RGB)
            with self._cond:
                self._frames.append((frame, t))
                self._down = None
                self.arrived += 1
                self._cond.notify_all()
        if cap is not None:
            cap.release()

    def mark_change(self, not_before: float) -> None:
        with self._cond:
            self._not_before = max(self._not_before, not_before)

    def read_frame(self, step: str = "reading a frame") -> tuple[np.ndarray, float]:
        """The next frame that arrived after the last one handed out and after the last :meth:`mark_change`.

        Raises:
            RigError: none within ``timeout_s`` (the message says whether the stream is down), or a wrong size.
        """
        self._check_open(step)
        c = self.config
        deadline = time.monotonic() + c.timeout_s
        with self._cond:
            while True:
                after = max(self._last_t, self._not_before)
                for frame, t in self._frames:
                    if t > after:
                        self._last_t = t
                        self._frames_read += 1
                        break
                else:
                    left = deadline - time.monotonic()
                    if left <= 0:
                        why = f"the stream is down ({self._down})" if self._down else "the stream sends no frames"
                        raise RigError(f"{self.label}: no frame within {c.timeout_s:g} s during {step}: {why}; "
                                       "outputs written so far are kept (lft render --resume goes on once the "
                                       "camera is back)")
                    self._cond.wait(left)
                    continue
                break
        return self.to_codes(frame), t

    def _request(self, body: dict | None) -> float | None:
        import json
        import urllib.request

        if self.config.control is None:
            return None
        data = None if body is None else json.dumps(body).encode()
        req = urllib.request.Request(self.config.control, data=data, method="GET" if body is None else "POST",
                                     headers={"Content-Type": "application/json"})
        with urllib.request.urlopen(req, timeout=self.config.timeout_s) as answer:
            value = json.loads(answer.read().decode()).get("exposure")
        return None if value is None else float(value)

    def _get_exposure(self) -> float | None:
        return self._request(None)

    def _set_exposure(self, value: float) -> float | None:
        return self._request({"exposure": float(value)})

    def _release(self) -> None:
        self._stop.set()
        if self._reader is not None:
            self._reader.join(timeout=self.config.timeout_s + 1.0)

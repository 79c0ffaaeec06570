"""Recording the frames a page shows to an MP4 file (the page's "record" button).

Frames are handed over as they are shown (8-bit RGB) and written by a thread of their own, so recording never
slows the live loop; the file is written atomically (:func:`lftransfer.imageio_utils.write_video`) and appears
when the recording stops. The video plays at the frame rate the loop had just before the recording began (an
encoder needs its rate first); the finished recording says how many frames it holds over how many seconds.
"""

from __future__ import annotations

import logging
import queue
import threading
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

__all__ = ["Recorder", "Recording"]

log = logging.getLogger(__name__)
MAX_QUEUED = 64          # frames waiting for the encoder; more are dropped (and counted) rather than stall the loop


@dataclass(frozen=True)
class Recording:
    """A finished recording.

    Attributes:
        path: the MP4 file (None: it failed, see ``error``).
        frames: frames written.
        dropped: frames shown but not written (the encoder fell behind).
        seconds: wall-clock from the first frame to the last.
        fps: the video's frame rate.
        error: why it failed, or None.
    """

    path: Path | None
    frames: int
    dropped: int
    seconds: float
    fps: float
    error: str | None = None

    def message(self) -> dict:
        return {"type": "recorded", "path": None if self.path is None else str(self.path), "frames": self.frames,
                "dropped": self.dropped, "seconds": round(self.seconds, 2), "fps": round(self.fps, 2),
                "error": self.error}


class Recorder:
    """One recording at a time: :meth:`start`, :meth:`add` per shown frame, :meth:`stop`."""

    def __init__(self) -> None:
        self._queue: queue.Queue | None = None
        self._thread: threading.Thread | None = None
        self._result: dict = {}
        self._path: Path | None = None
        self._fps = 0.0
        self._frames = self._dropped = 0
        self._first = self._last = 0.0

    @property
    def recording(self) -> bool:
        return self._queue is not None

    def start(self, path: Path, fps: float) -> None:
        """Begin recording into ``path`` (an MP4) at ``fps`` frames per second of video (>= 1)."""
        from lftransfer.imageio_utils import write_video

        if self.recording:
            raise RuntimeError("a recording is running already")
        self._path, self._fps = Path(path), max(1.0, float(fps))
        self._frames = self._dropped = 0
        self._first = self._last = 0.0
        self._result = {}
        q: queue.Queue = queue.Queue(maxsize=MAX_QUEUED)
        self._queue = q

        def frames():
            while (item := q.get()) is not None:
                yield item

        def run() -> None:
            try:
                self._path.parent.mkdir(parents=True, exist_ok=True)
                write_video(self._path, frames(), self._fps)
            except Exception as exc:  # noqa: BLE001 - reported with the recording
                log.warning("recording failed", exc_info=True)
                self._result["error"] = f"{type(exc).__name__}: {exc}"
                while q.get() is not None:      # drain, so that add() and stop() never block
                    pass

        self._thread = threading.Thread(target=run, name="lft-record", daemon=True)
        self._thread.start()

    def add(self, image: np.ndarray) -> None:
        """Hand over a shown frame (H, W, 3) uint8; dropped when the encoder is behind."""
        if self._queue is None:
            return
        now = time.perf_counter()
        try:
            self._queue.put_nowait(np.ascontiguousarray(image[..., :3]))
            self._frames += 1
            self._first = self._first or now
            self._last = now
        except queue.Full:
            self._dropped += 1

    def stop(self, timeout: float = 120.0) -> Recording:
        """Finish the file and return what was recorded."""
        if self._queue is None:
            raise RuntimeError("no recording is running")
        q, self._queue = self._queue, None
        q.put(None)
        self._thread.join(timeout)
        error = self._result.get("error")
        if error is None and self._frames == 0:
            error = "no frame was shown while recording"
        return Recording(path=None if error else self._path, frames=self._frames, dropped=self._dropped,
                         seconds=self._last - self._first, fps=self._fps, error=error)

"""The twin's cameras: frames at their own rate, late by the display-to-capture latency, with real faults.

A :class:`TwinCamera` runs a clock of its own (``fps``). For each tick at time t it looks at what the projector
showed at t minus the latency (plus a jitter drawn per frame, never going back in time), asks the world for the
radiance of that state (:class:`~.world.TwinWorld`: rendered once per change) and makes a frame of it: the LF
camera exposes it with fresh sensor noise (12-bit codes), the view camera writes linear 16-bit codes. The frame
goes to every client connected to the camera's stream (:mod:`.server`), unless it is dropped (``drop_rate``).

A render takes longer than a frame when the state is new; the camera then delivers no frame in between (as a
camera that is busy), and a frame that comes out after a long render is made again if the screen changed
meanwhile, so no frame shows a state older than its arrival time minus the latency.

Each frame carries its timestamp, as machine-vision and IP cameras stamp theirs: the moment of the screen it shows
plus the latency drawn for it (the time it would leave the camera with no render or encoder in the way). The
stream writes it as the frame's presentation time (:mod:`.server`), so a rig that reads stream timestamps
(``timestamps = "stream"``) judges a frame by when it was taken, not by when a loaded machine got round to
reading it.

Faults: the stream stops ``stop_after_s`` seconds after the twin started (every client is cut off and new
connections are refused) and comes back after ``down_for_s`` seconds (None: never).
"""

from __future__ import annotations

import logging
import math
import queue
import threading
import time
import zlib
from dataclasses import dataclass
from typing import Callable

import numpy as np

__all__ = ["CameraTiming", "TwinCamera", "planar"]

_log = logging.getLogger(__name__)


@dataclass(frozen=True)
class CameraTiming:
    """A twin camera's timing and faults.

    Attributes:
        fps: frames per second.
        latency_s: display-to-capture latency, seconds (the projector's input lag and the camera's own delay), up to the frame leaving the camera: the twin's own
            time to make and encode a frame counts in it.
        jitter_s: each frame's latency is drawn uniformly within latency_s +- jitter_s.
        drop_rate: probability that a frame is lost on its way.
        stop_after_s: the stream stops this long after the twin started, or None.
        down_for_s: ... and comes back after this long, or None (never).
    """

    fps: float
    latency_s: float = 0.06
    jitter_s: float = 0.005
    drop_rate: float = 0.0
    stop_after_s: float | None = None
    down_for_s: float | None = None

    def down_at(self, elapsed: float) -> bool:
        """Whether the stream is stopped ``elapsed`` seconds after the start."""
        if self.stop_after_s is None or elapsed < self.stop_after_s:
            return False
        return self.down_for_s is None or elapsed < self.stop_after_s + self.down_for_s


def planar(image: np.ndarray) -> np.ndarray:
    """(H, W, 3) -> (3 H, W): the R, G and B planes one above the other (a stream's GRAY16LE frame)."""
    return np.ascontiguousarray(np.moveaxis(image, -1, 0).reshape(-1, image.shape[1]))


class TwinCamera:
    """One camera of the twin and the clients of its stream.

    Args:
        name: "lf", "view", or "lf/NAME" (the LF camera of a later light field interface).
        timing: its clock and faults.
        state: ``state(t) -> (key, images)``: what the projectors showed at monotonic time t.
        render: ``render(images) -> radiance`` (the world's, cached per state).
        frame: ``frame(radiance) -> (3 H, W) uint16`` the frame sent (exposure, noise, codes).
        seed: seed of the jitter and the drops.
    """

    QUEUE = 2                          # frames queued per client: a client (or its encoder) that falls behind
    #                                    loses the oldest, as a camera's own small buffer does; it never gets a
    #                                    backlog of old frames late

    def __init__(self, name: str, timing: CameraTiming, state: Callable[[float], tuple[str, np.ndarray]],
                 render: Callable[[np.ndarray], np.ndarray], frame: Callable[[np.ndarray], np.ndarray],
                 seed: int = 0) -> None:
        self.name = name
        self.timing = timing
        self._state = state
        self._render = render
        self._frame = frame
        stream = {"lf": 1, "view": 2}.get(name, 3 + zlib.crc32(name.encode()) % 100_000)   # another LF camera's
        self._rng = np.random.default_rng([seed, 17, stream])
        self._clients: set[queue.Queue] = set()
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self.down = False
        self.published = 0
        self.dropped = 0
        self.rerendered = 0
        self.missed = 0
        self.overrun = 0                   # frames lost because a client fell behind
        self.shape: tuple[int, int] | None = None
        self.delay_s = 0.0                 # mean time from a tick to its frame on the wire (exposure, encoding)
        self._started = time.monotonic()
        self._thread = threading.Thread(target=self._run, name=f"twin-{name}", daemon=True)

    def start(self, started: float) -> None:
        """Start the clock; faults count from ``started`` (monotonic seconds)."""
        self._started = started
        self._thread.start()

    # -- clients --------------------------------------------------------------------------------------------
    def subscribe(self) -> queue.Queue | None:
        """A queue of the frames to come ((tick time, (3 H, W) uint16), None at the end), or None while the stream
        is stopped."""
        with self._lock:
            if self.down:
                return None
            q: queue.Queue = queue.Queue(maxsize=self.QUEUE)
            self._clients.add(q)
            return q

    def unsubscribe(self, q: queue.Queue) -> None:
        with self._lock:
            self._clients.discard(q)

    @property
    def clients(self) -> int:
        with self._lock:
            return len(self._clients)

    def _publish(self, frame) -> None:
        """Queue ``frame`` for every client; where a client's queue is full its oldest frame is lost."""
        with self._lock:
            for q in list(self._clients):
                while True:
                    try:
                        q.put_nowait(frame)
                        break
                    except queue.Full:
                        try:
                            q.get_nowait()
                            self.overrun += 1
                        except queue.Empty:
                            pass

    # -- the clock ------------------------------------------------------------------------------------------
    def _latency(self) -> float:
        t = self.timing
        return max(0.0, t.latency_s + (self._rng.uniform(-t.jitter_s, t.jitter_s) if t.jitter_s > 0 else 0.0))

    def _run(self) -> None:
        period = 1.0 / self.timing.fps
        next_t = time.monotonic()
        last_state = -math.inf
        while not self._stop.is_set():
            self._stop.wait(max(0.0, next_t - time.monotonic()))
            if self._stop.is_set():
                break
            now = time.monotonic()
            down = self.timing.down_at(now - self._started)
            if down != self.down:
                with self._lock:
                    self.down = down
                _log.warning("twin %s camera: stream %s", self.name, "stopped" if down else "back")
                if down:
                    self._publish(None)
                    with self._lock:
                        self._clients.clear()
            if down or not self.clients:          # nobody watches: no frame to make (the clock goes on)
                next_t = now + period
                continue
            try:
                frame = self._make(now, last_state)
            except Exception:  # noqa: BLE001  (a failed render must not end the camera)
                _log.exception("twin %s camera: a frame failed", self.name)
                next_t = time.monotonic() + period
                continue
            if frame is None:
                next_t = time.monotonic()
                continue
            last_state, made, stamp, image = frame
            if self.timing.drop_rate > 0 and self._rng.random() < self.timing.drop_rate:
                self.dropped += 1
            else:
                self.shape = image.shape
                self._publish((made, stamp, image))
                self.published += 1
            next_t += period
            if next_t < time.monotonic():        # a long render: the ticks it covered are gone
                next_t = time.monotonic()

    def _make(self, now: float, last_state: float) -> tuple[float, float, float, np.ndarray] | None:
        """(state time, frame time, timestamp, frame) of a tick at ``now``; the timestamp is the state time plus the
        frame's latency. A frame whose making (a render of a new state) let the state change meanwhile is made
        again from the state of its new moment; after 3 tries it is not sent (a missed frame): a frame never leaves
        showing a state older than its moment minus the latency."""
        for _ in range(3):
            latency = self._latency()
            # the frame leaves latency after the state it shows: its own encoding time counts in. Never a moment
            # still to come: where encoding takes longer than the latency, the frame shows the present (asking
            # the screen about the future would wait for it, and the wait would count as encoding time)
            t_state = max(last_state, now + min(0.0, self.delay_s - latency))
            key, image = self._state(t_state)
            radiance = self._render(image)
            after = time.monotonic()
            if self._state(max(t_state, after + min(0.0, self.delay_s - latency)))[0] == key:
                return t_state, time.monotonic(), t_state + latency, self._frame(radiance)
            self.rerendered += 1
            now = after
        self.missed += 1
        return None

    def note_sent(self, tick_to_wire_s: float) -> None:
        """A client's encoder says how long a frame took from its making to the wire (a running mean is kept)."""
        self.delay_s = tick_to_wire_s if self.delay_s == 0 else 0.8 * self.delay_s + 0.2 * tick_to_wire_s

    def stop(self) -> None:
        self._stop.set()
        self._publish(None)
        if self._thread.is_alive():
            self._thread.join(timeout=5.0)

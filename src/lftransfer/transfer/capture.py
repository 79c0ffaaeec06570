"""The capture half of a live frame, and the worker that runs it at the devices' own rate (docs/architecture.md,
"The live loop").

One capture: encode the synthetic light field the projector is to show (skipped when it is the one shown
already), project it, pose the real scene (the simulated rig moves its real objects; a physical one moves by
itself), capture the LF camera and decode it, capture the view camera. :func:`capture_once` is that capture;
the synchronous loop calls it inside each frame, and :class:`CaptureWorker` calls it again and again on its own
thread, so that the render loop (:class:`lftransfer.transfer.live.LiveTransfer` with ``loop="decoupled"``) runs at
its own rate with the newest capture it has.

Each capture remembers which synthetic light field lit it (``projected_version``: the version of the synthetic
scene it was rendered from) and when it began, so that a frame can say how old its capture was and when a change
of the synthetic scene first reached the real objects' light (:mod:`lftransfer.transfer.latency`).
"""

from __future__ import annotations

import logging
import threading
import time
from collections import deque
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Callable, Iterator

import numpy as np

from lftransfer.lightfield import LightField
from lftransfer.rig.base import Rig, RigError
from lftransfer.rig.requests import RealScene
from lftransfer.transfer.timer import StageTimer, rate_hz

__all__ = ["Capture", "CaptureWorker", "Projection", "capture_once"]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Projection:
    """A synthetic light field for the projector, and the version of the synthetic scene it was rendered from.

    Attributes:
        lf: Ls, (K, V, U, 3) radiance; the all-zero light field means a black projector.
        version: the synthetic scene's version (0 = as it started; each pose change or edit adds one).
        black: whether it is the black start (projected as the device's black image, not encoded).
    """

    lf: LightField
    version: int
    black: bool = False


@dataclass(frozen=True)
class Capture:
    """One capture of the real scene under one projection.

    Attributes:
        index: captures since the loop started (0 = the first).
        captured_lf: R, the decoded LF camera image (real point light plus the response to the projection).
        captured_raw: the LF camera image (device integers).
        real_view: (H, W, 3) float32 view camera radiance under the same projection.
        projection: what the projector showed (:class:`Projection`).
        projected_image: the projector image shown (device integers).
        clipped_fraction: fraction of lit samples of the projection above the projector's range (clipped).
        real_time_s: the scene time the real scene was posed at, seconds.
        started_s: ``time.perf_counter()`` when the projection was shown (the capture's moment), seconds.
        finished_s: ``time.perf_counter()`` when the capture was decoded and ready, seconds.
        timings_s: seconds per stage: "encode" (0 when the projection was shown already), "capture", "decode",
            "capture_view".
    """

    index: int
    captured_lf: LightField
    captured_raw: np.ndarray
    real_view: np.ndarray
    projection: Projection
    projected_image: np.ndarray
    clipped_fraction: float
    real_time_s: float
    started_s: float
    finished_s: float
    timings_s: dict[str, float] = field(default_factory=dict)


class _Encoded:
    """The projector image of the newest projection and its clipped fraction, found once."""

    def __init__(self) -> None:
        self.projection: Projection | None = None
        self.image: np.ndarray | None = None
        self.clipped = 0.0


def _clipped(projection: Projection, max_radiance: float) -> float:
    """Fraction of the projection's lit samples above the projector's range."""
    lit = projection.lf.data[projection.lf.data > 0]
    return float(np.mean(lit > max_radiance)) if lit.size else 0.0


def capture_once(rig: Rig, encoder: Callable, decoder: Callable, projection: Projection, *, index: int,
                 real_time_s: float, max_radiance: float, pose_real: bool = True, cache: _Encoded | None = None,
                 timer: StageTimer | None = None) -> Capture:
    """Project ``projection``, capture the LF camera and the view camera, decode.

    Args:
        rig: the rig (only the caller's thread uses it meanwhile).
        encoder: LightField -> projector image (the rig model's).
        decoder: LF camera image -> LightField (the rig model's).
        projection: what to project.
        index: the capture's number.
        real_time_s: the scene time the real scene is posed at, seconds.
        max_radiance: the projector's largest radiance (for the clipped fraction).
        pose_real: pose the real scene first (``rig.setup(RealScene(real_time_s))``); False: the caller did.
        cache: the projector image of the projection shown last (encoding is skipped when it is the same); None:
            encode every time.
        timer: a stage timer to add the stages to (a new one when None).

    Returns:
        :class:`Capture` (its ``timings_s`` are this capture's own stages).
    """
    own = StageTimer()
    if cache is not None and cache.projection is projection and cache.image is not None:
        pattern, clipped = cache.image, cache.clipped
        own.totals["encode"] = 0.0
    else:
        with own("encode"):
            pattern = rig.info.black() if projection.black else encoder(projection.lf)
        clipped = _clipped(projection, max_radiance)
        if cache is not None:
            cache.projection, cache.image, cache.clipped = projection, pattern, clipped
    if pose_real:
        rig.setup(RealScene(time_s=float(real_time_s)))
    started = time.perf_counter()
    rig.project(pattern)
    with own("capture"):
        raw = rig.capture_lf().codes
    with own("decode"):
        captured = decoder(raw)
    with own("capture_view"):
        real_view = rig.capture_view().radiance
    if timer is not None:
        for k, v in own.totals.items():
            timer.totals[k] = timer.totals.get(k, 0.0) + v
    return Capture(index=index, captured_lf=captured, captured_raw=raw, real_view=real_view, projection=projection,
                   projected_image=pattern, clipped_fraction=clipped,
                   real_time_s=float(real_time_s), started_s=started,
                   finished_s=time.perf_counter(), timings_s=dict(own.totals))


class CaptureWorker:
    """Captures on its own thread, one after another, each under the newest projection it was handed.

    The render loop hands it each new synthetic light field (:meth:`show`) and takes the newest capture
    (:meth:`newest`, or :meth:`wait` for one newer than it has); neither waits for the other. Only the worker's
    thread uses the rig while it runs; whoever else needs the rig (the bounce layers, moving a simulated real
    object) holds it with :meth:`holding`, which waits for the capture in progress and keeps the next one back.

    Args:
        rig: the rig.
        encoder: LightField -> projector image.
        decoder: LF camera image -> LightField.
        first: the projection to start with.
        max_radiance: the projector's largest radiance.
        real_time: returns the scene time the real scene is to be posed at for the next capture (the newest render
            frame's time), seconds.
        keep_rate_of: captures over which :attr:`rate_hz` is measured.
    """

    def __init__(self, rig: Rig, encoder: Callable, decoder: Callable, first: Projection, *, max_radiance: float,
                 real_time: Callable[[], float], keep_rate_of: int = 8) -> None:
        self.rig, self.encoder, self.decoder = rig, encoder, decoder
        self.max_radiance = max_radiance
        self._real_time = real_time
        self._projection = first
        self._newest: Capture | None = None
        self._cache = _Encoded()
        self._lock = threading.Lock()             # guards _projection and _newest
        self._fresh = threading.Condition(self._lock)
        self._rig_lock = threading.RLock()        # held for each capture, and by holding()
        self._stop = threading.Event()
        self._holders = 0                         # holding() and paused() in progress (guarded by _lock)
        self._held = False                        # hold(True): until hold(False)
        self._thread: threading.Thread | None = None
        self._starts: deque[float] = deque(maxlen=keep_rate_of + 1)
        self.error: BaseException | None = None
        self.count = 0

    # -- the render loop's side -----------------------------------------------------------------------------------
    def show(self, projection: Projection) -> None:
        """Project this from the next capture on (the capture in progress keeps its own)."""
        with self._lock:
            self._projection = projection

    def newest(self) -> Capture | None:
        """The newest finished capture, or None before the first."""
        self._raise()
        with self._lock:
            return self._newest

    def wait(self, after: int = -1, timeout: float | None = None) -> Capture:
        """Block until a capture with index > ``after`` is finished, and return the newest.

        Raises:
            TimeoutError: none came within ``timeout`` seconds.
            RuntimeError: the worker stopped on an error (its message).
        """
        deadline = None if timeout is None else time.perf_counter() + timeout
        with self._fresh:
            while self._newest is None or self._newest.index <= after:
                self._raise()
                if self._stop.is_set():
                    raise RuntimeError("the capture worker was stopped")
                left = None if deadline is None else deadline - time.perf_counter()
                if left is not None and left <= 0:
                    raise TimeoutError(f"no new capture within {timeout:g} s")
                self._fresh.wait(0.1 if left is None else min(left, 0.1))
            return self._newest

    @property
    def rate_hz(self) -> float:
        """Captures per second over the last few (0 before two have begun)."""
        return rate_hz(self._starts, last=len(self._starts))

    @contextmanager
    def holding(self) -> Iterator[Rig]:
        """The rig to the caller alone: waits for the capture in progress; captures resume on exit (unless
        something else still keeps them back)."""
        with self.paused(), self._rig_lock:
            yield self.rig

    def hold(self, held: bool) -> None:
        """No new capture begins while held (the one in progress finishes), until ``hold(False)``."""
        with self._lock:
            self._held = held

    @contextmanager
    def paused(self) -> Iterator[None]:
        """No new capture begins meanwhile (the one in progress finishes); unlike :meth:`holding`, nothing waits.
        Nested and overlapping pauses, holds and :meth:`hold` each keep captures back until all have ended."""
        with self._lock:
            self._holders += 1
        try:
            yield
        finally:
            with self._lock:
                self._holders -= 1

    def _kept_back(self) -> bool:
        with self._lock:
            return self._held or self._holders > 0

    # -- the thread -------------------------------------------------------------------------------------------------
    def start(self) -> None:
        if self._thread is not None:
            return
        self._thread = threading.Thread(target=self._run, name="lft-capture", daemon=True)
        self._thread.start()

    def stop(self, timeout: float = 120.0) -> None:
        """Stop after the capture in progress (waits for it up to ``timeout`` seconds)."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout)
            if self._thread.is_alive():
                log.warning("the capture worker did not stop within %g s", timeout)

    def _raise(self) -> None:
        """The worker's error, as a :class:`~lftransfer.rig.base.RigError` where the rig failed (a device, a dead
        simulator: the faces end on it in one line), else a RuntimeError."""
        if self.error is not None:
            kind = RigError if isinstance(self.error, RigError) else RuntimeError
            raise kind(f"the capture worker stopped: {type(self.error).__name__}: {self.error}") from self.error

    def _run(self) -> None:
        while not self._stop.is_set():
            if self._kept_back():
                time.sleep(0.005)
                continue
            try:
                with self._rig_lock:
                    if self._stop.is_set():
                        return
                    with self._lock:
                        projection = self._projection
                    self._starts.append(time.perf_counter())
                    cap = capture_once(self.rig, self.encoder, self.decoder, projection, index=self.count,
                                       real_time_s=self._real_time(), max_radiance=self.max_radiance,
                                       cache=self._cache)
                with self._fresh:
                    self._newest = cap
                    self.count += 1
                    self._fresh.notify_all()
            except BaseException as exc:  # noqa: BLE001 - handed to the render loop, which raises it
                log.warning("capture failed", exc_info=True)
                with self._fresh:
                    self.error = exc
                    self._fresh.notify_all()
                return

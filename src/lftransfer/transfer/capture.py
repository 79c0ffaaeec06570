"""The capture half of a live frame, and the worker that runs it at the devices' own rate (docs/architecture.md,
"The live loop").

One capture: encode the synthetic light field the projector is to show (skipped when it is the one shown
already), project it, pose the real scene (the simulated rig moves its real objects; a physical one moves by
itself), capture the LF camera and decode it, capture the view camera; with several light field interfaces, every
projector and every LF camera, then the one view camera. :func:`capture_once` is that capture;
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
from typing import Callable, Iterator, Sequence

import numpy as np

from lftransfer.lightfield import LightField
from lftransfer.rig.base import Rig, RigError
from lftransfer.rig.requests import RealScene
from lftransfer.transfer.timer import StageTimer, rate_hz

__all__ = ["Capture", "CaptureWorker", "Projection", "capture_once"]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Projection:
    """The synthetic light field each projector is to show, and the version of the synthetic scene it was rendered
    from.

    Attributes:
        lfs: Ls of each light field interface, in the scene's order (one for one interface), each (K, V, U, 3)
            radiance; an all-zero light field means a black projector.
        version: the synthetic scene's version (0 = as it started; each pose change or edit adds one).
        black: whether it is the black start (projected as each device's black image, not encoded).
    """

    lfs: tuple[LightField, ...]
    version: int
    black: bool = False

    @property
    def lf(self) -> LightField:
        """The first interface's light field (the only one with one interface)."""
        return self.lfs[0]


@dataclass(frozen=True)
class Capture:
    """One capture of the real scene under one projection (every interface's LF camera, the one view camera).

    Attributes:
        index: captures since the loop started (0 = the first).
        captured_lfs: R of each interface, the decoded LF camera image (real point light plus the response to every
            projection).
        captured_raws: each interface's LF camera image (device integers).
        real_view: (H, W, 3) float32 view camera radiance under the same projections.
        projection: what the projectors showed (:class:`Projection`).
        projected_images: each projector's image shown (device integers).
        clipped_fraction: fraction of lit samples of the projections above their projectors' range (clipped).
        real_time_s: the scene time the real scene was posed at, seconds.
        started_s: ``time.perf_counter()`` when the projection was shown (the capture's moment), seconds.
        finished_s: ``time.perf_counter()`` when the capture was decoded and ready, seconds.
        timings_s: seconds per stage: "encode" (0 when the projection was shown already), "capture", "decode",
            "capture_view".
    """

    index: int
    captured_lfs: tuple[LightField, ...]
    captured_raws: tuple[np.ndarray, ...]
    real_view: np.ndarray
    projection: Projection
    projected_images: tuple[np.ndarray, ...]
    clipped_fraction: float
    real_time_s: float
    started_s: float
    finished_s: float
    timings_s: dict[str, float] = field(default_factory=dict)

    @property
    def captured_lf(self) -> LightField:
        """The first interface's R."""
        return self.captured_lfs[0]

    @property
    def captured_raw(self) -> np.ndarray:
        """The first interface's LF camera image."""
        return self.captured_raws[0]

    @property
    def projected_image(self) -> np.ndarray:
        """The first interface's projector image."""
        return self.projected_images[0]


class _Encoded:
    """The projector images of the newest projection and its clipped fraction, found once."""

    def __init__(self) -> None:
        self.projection: Projection | None = None
        self.images: tuple[np.ndarray, ...] | None = None
        self.clipped = 0.0


def _clipped(projection: Projection, max_radiances: Sequence[float]) -> float:
    """Fraction of the projection's lit samples (every interface's) above their projector's range."""
    lit = [(lf.data[lf.data > 0], peak) for lf, peak in zip(projection.lfs, max_radiances)]
    count = sum(v.size for v, _ in lit)
    return float(sum(np.count_nonzero(v > peak) for v, peak in lit) / count) if count else 0.0


def capture_once(rigs: Sequence[Rig], encoders: Sequence[Callable], decoders: Sequence[Callable],
                 projection: Projection, *, index: int, real_time_s: float, max_radiances: Sequence[float],
                 pose_real: bool = True, cache: _Encoded | None = None, timer: StageTimer | None = None) -> Capture:
    """Project ``projection`` through every interface, capture every LF camera and the view camera, decode.

    Args:
        rigs: one rig per light field interface, in the scene's order (one for one interface; several share one
            real world and one view camera, the first's is used). Only the caller's thread uses them meanwhile.
        encoders: LightField -> projector image, each interface's (its rig model's).
        decoders: LF camera image -> LightField, each interface's.
        projection: what to project (a light field per interface).
        index: the capture's number.
        real_time_s: the scene time the real scene is posed at, seconds.
        max_radiances: each projector's largest radiance (for the clipped fraction).
        pose_real: pose the real scene first (``rig.setup(RealScene(real_time_s))``); False: the caller did.
        cache: the projector images of the projection shown last (encoding is skipped when it is the same); None:
            encode every time.
        timer: a stage timer to add the stages to (a new one when None).

    Returns:
        :class:`Capture` (its ``timings_s`` are this capture's own stages).
    """
    if not len(rigs) == len(encoders) == len(decoders) == len(projection.lfs):
        raise ValueError(f"capture_once: {len(rigs)} rigs, {len(encoders)} encoders, {len(decoders)} decoders and "
                         f"{len(projection.lfs)} light fields to project")
    own = StageTimer()
    if cache is not None and cache.projection is projection and cache.images is not None:
        patterns, clipped = cache.images, cache.clipped
        own.totals["encode"] = 0.0
    else:
        with own("encode"):
            patterns = tuple(rig.info.black() if projection.black else enc(lf)
                             for rig, enc, lf in zip(rigs, encoders, projection.lfs))
        clipped = _clipped(projection, max_radiances)
        if cache is not None:
            cache.projection, cache.images, cache.clipped = projection, patterns, clipped
    if pose_real:
        for rig in rigs:
            rig.setup(RealScene(time_s=float(real_time_s)))
    started = time.perf_counter()
    for rig, pattern in zip(rigs, patterns):
        rig.project(pattern)
    with own("capture"):
        raws = tuple(rig.capture_lf().codes for rig in rigs)
    with own("decode"):
        captured = tuple(dec(raw) for dec, raw in zip(decoders, raws))
    with own("capture_view"):
        real_view = rigs[0].capture_view().radiance
    if timer is not None:
        for k, v in own.totals.items():
            timer.totals[k] = timer.totals.get(k, 0.0) + v
    return Capture(index=index, captured_lfs=captured, captured_raws=raws, real_view=real_view, projection=projection,
                   projected_images=patterns, clipped_fraction=clipped,
                   real_time_s=float(real_time_s), started_s=started,
                   finished_s=time.perf_counter(), timings_s=dict(own.totals))


class CaptureWorker:
    """Captures on its own thread, one after another, each under the newest projection it was handed.

    The render loop hands it each new synthetic light field (:meth:`show`) and takes the newest capture
    (:meth:`newest`, or :meth:`wait` for one newer than it has); neither waits for the other. Only the worker's
    thread uses the rigs while it runs; whoever else needs them (the bounce layers, moving a simulated real
    object) holds it with :meth:`holding`, which waits for the capture in progress and keeps the next one back.

    Args:
        rigs: one rig per light field interface (:func:`capture_once`).
        encoders: LightField -> projector image, each interface's.
        decoders: LF camera image -> LightField, each interface's.
        first: the projection to start with.
        max_radiances: each projector's largest radiance.
        real_time: returns the scene time the real scene is to be posed at for the next capture (the newest render
            frame's time), seconds.
        keep_rate_of: captures over which :attr:`rate_hz` is measured.
    """

    def __init__(self, rigs: Sequence[Rig], encoders: Sequence[Callable], decoders: Sequence[Callable],
                 first: Projection, *, max_radiances: Sequence[float], real_time: Callable[[], float],
                 keep_rate_of: int = 8) -> None:
        self.rigs, self.encoders, self.decoders = list(rigs), list(encoders), list(decoders)
        self.max_radiances = list(max_radiances)
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
    def holding(self) -> Iterator[list[Rig]]:
        """The rigs (one per interface) to the caller alone: waits for the capture in progress; captures resume on
        exit (unless something else still keeps them back)."""
        with self.paused(), self._rig_lock:
            yield self.rigs

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
                    cap = capture_once(self.rigs, self.encoders, self.decoders, projection, index=self.count,
                                       real_time_s=self._real_time(), max_radiances=self.max_radiances,
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

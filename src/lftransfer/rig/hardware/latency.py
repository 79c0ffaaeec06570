"""Display-to-capture latency: how long after :meth:`ProjectorWindow.show` returns a camera frame shows the image.

:func:`measure_latency` projects black, then a bright marker (full white by default) and reads the camera
continuously (so no frames pile up in its driver) until a frame's mean brightness crosses the midpoint between
the black and the marker levels; the delay is the time from ``show`` returning (the buffer swap carried out)
to that frame's arrival. It does this ``tries`` times, each bounded by ``timeout_s``, each marker shown at a random
phase of the camera's frame period (measured while priming), so the delays spread over a frame rather than lock
to the camera's frame clock: the median is the latency plus about half a frame, the largest about a whole frame
more, which is what ``settle_s`` has to cover.

:func:`calibrate_latency` opens the projector and the LF camera from a rig file, measures, and writes
``projector.settle_s`` back into the file: the largest delay plus a margin (25 % of it, at least 20 ms),
rounded up to a whole millisecond. The LF camera sees the projector through the focal-plane diffuser (the
:class:`~lftransfer.rig.requests.FocalPlaneDiffuser` set-up), or through the lens array onto any bright surface.
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Callable, Protocol

import numpy as np

from lftransfer.rig.base import RigError
from lftransfer.rig.hardware.operator import arranger
from lftransfer.rig.requests import FocalPlaneDiffuser, RealScene

__all__ = ["LatencyResult", "calibrate_latency", "measure_latency", "settle_time"]

_log = logging.getLogger(__name__)


class _Projector(Protocol):
    label: str
    shape: tuple[int, int, int]
    dtype: type

    def show(self, image: np.ndarray, step: str = ...) -> float | None: ...


class _Camera(Protocol):
    label: str

    def read_frame(self, step: str = ...) -> tuple[np.ndarray, float]: ...


@dataclass(frozen=True)
class LatencyResult:
    """Measured display-to-capture delays.

    Attributes:
        median_s: median delay, seconds.
        max_s: largest delay, seconds.
        samples: (tries,) the delays, seconds, in the order measured.
        black_level: mean camera code while the projector shows black.
        marker_level: mean camera code while it shows the marker.
        settle_s: the ``projector.settle_s`` written to the rig file (:func:`calibrate_latency`), else None.
        frame_s: the camera's frame period measured while priming, seconds (0 where unknown).
    """

    median_s: float
    max_s: float
    samples: tuple[float, ...]
    black_level: float
    marker_level: float
    settle_s: float | None = None
    frame_s: float = 0.0

    @property
    def latency_s(self) -> float:
        """The display-to-frame latency: the median delay less half a frame (the markers are shown at random
        phases of the camera's frame clock, so the wait for the next frame is uniform over one frame)."""
        return max(0.0, self.median_s - 0.5 * self.frame_s)

    def to_json(self) -> dict:
        """The result as JSON data (seconds), with :attr:`latency_s`."""
        return {"median_s": self.median_s, "max_s": self.max_s, "latency_s": self.latency_s,
                "frame_s": self.frame_s, "settle_s": self.settle_s, "samples": list(self.samples),
                "black_level": self.black_level, "marker_level": self.marker_level}


def settle_time(result: LatencyResult, margin: float = 0.25, min_margin_s: float = 0.02) -> float:
    """The ``settle_s`` a measured latency calls for: the largest delay plus a margin.

    Args:
        result: the measurement.
        margin: margin as a fraction of the largest delay.
        min_margin_s: the least margin, seconds.

    Returns:
        max_s + max(min_margin_s, margin * max_s), rounded up to a whole millisecond.
    """
    s = result.max_s + max(min_margin_s, margin * result.max_s)
    return math.ceil(s * 1000 - 1e-6) / 1000


def _marker_never_seen(camera: _Camera, projector: _Projector, timeout_s: float, levels: str) -> RigError:
    return RigError(f"{camera.label}: the camera never saw the projector's marker within {timeout_s:g} s "
                    f"(latency measurement, {projector.label}; {levels}): is the camera looking through the "
                    "array / is the projector on?")


def _level(camera: _Camera, step: str) -> tuple[float, float]:
    """The camera's next frame's mean code and its arrival (monotonic seconds)."""
    frame, t = camera.read_frame(step)
    return float(np.mean(frame)), t


def _levels(projector: _Projector, camera: _Camera, black: np.ndarray, marker: np.ndarray, timeout_s: float,
            prime_s: float, min_contrast: float, step: str) -> tuple[float, float, float]:
    """The camera's mean code on black and on the marker, and its frame period (0 where unknown), from frames
    watched for ``prime_s`` on each.

    Raises:
        RigError: the camera never saw the marker within ``timeout_s``.
    """
    arrivals: list[float] = []

    def watch(seconds: float, at_least: int = 3) -> float:
        values: list[float] = []
        end = time.monotonic() + seconds
        while time.monotonic() < end or len(values) < at_least:
            v, t = _level(camera, step)
            values.append(v)
            arrivals.append(t)
        return float(np.mean(values[-at_least:]))

    projector.show(black, step=step)
    b = watch(prime_s)
    projector.show(marker, step=step)
    deadline = time.monotonic() + timeout_s
    peak = b
    while True:
        v, t = _level(camera, step)
        peak = max(peak, v)
        if v - b > min_contrast * max(v, 1.0):
            break
        if t > deadline:
            raise _marker_never_seen(camera, projector, timeout_s, f"mean code {b:.1f} on black, at most "
                                     f"{peak:.1f} on the marker")
    w = max(watch(prime_s), v)
    if not w - b > min_contrast * max(w, 1.0):
        raise _marker_never_seen(camera, projector, timeout_s, f"mean code {b:.1f} on black, {w:.1f} on the "
                                 "marker")
    _log.info("latency: black level %.1f, marker level %.1f", b, w)
    # the camera's frame period: each marker is shown at a random phase of it, so that the delays sample the whole
    # frame interval instead of locking to the frame clock (reading a frame, then showing, would always land at
    # the same phase and round every delay up to the same frame)
    gaps = np.diff(np.asarray(arrivals))
    gaps = gaps[gaps > 0.25 * gaps.max()] if gaps.size else gaps      # not the frames a driver had buffered
    return b, w, float(np.median(gaps)) if gaps.size else 0.0


def _one_delay(projector: _Projector, camera: _Camera, black: np.ndarray, marker: np.ndarray,
               levels: tuple[float, float, float], period: float, rng: np.random.Generator, timeout_s: float,
               step: str) -> float:
    """One delay, seconds: black until the camera sees it, one more dark frame, a random phase of the frame period,
    then the marker until the camera's mean code crosses the middle of ``levels`` (black, middle, marker).

    Raises:
        RigError: the camera never saw black again, or never the marker, within ``timeout_s``.
    """
    b, mid, w = levels
    projector.show(black, step=step)
    deadline = time.monotonic() + timeout_s
    while True:
        v, t = _level(camera, step)
        if v < mid:
            break
        if t > deadline:
            raise RigError(f"{camera.label}: the camera never saw the projector go black again within "
                           f"{timeout_s:g} s (latency measurement, {projector.label}; mean code {v:.1f}, "
                           f"black is {b:.1f})")
    _level(camera, step)                        # one more dark frame: the next one starts from black
    if period > 0:
        time.sleep(rng.uniform(0.0, min(period, timeout_s / 4)))
    t0 = projector.show(marker, step=step)
    if t0 is None:
        t0 = time.monotonic()
    deadline = t0 + timeout_s
    while True:
        v, t = _level(camera, step)
        if v > mid:
            break
        if t > deadline:
            raise _marker_never_seen(camera, projector, timeout_s, f"mean code {v:.1f}, marker is "
                                     f"{w:.1f}, black {b:.1f}")
    return max(0.0, t - t0)


def measure_latency(projector: _Projector, camera: _Camera, tries: int = 20, *, timeout_s: float = 2.0,
                    marker: np.ndarray | None = None, prime_s: float = 0.3, min_contrast: float = 0.02,
                    progress: Callable[[int, int, float], None] | None = None) -> LatencyResult:
    """Measure how long after a projection the camera's frames show it.

    Args:
        projector: an open :class:`~lftransfer.rig.hardware.projector.ProjectorWindow` (or any object with
            ``label``, ``shape``, ``dtype`` and ``show(image) -> monotonic time presented``).
        camera: an open :class:`~lftransfer.rig.hardware.camera.Camera` (``label``,
            ``read_frame(step) -> (codes, monotonic time)``) that sees the projector.
        tries: delays measured, >= 1.
        timeout_s: longest wait for the camera to see one change, seconds.
        marker: (H, W, 3) projector image shown as the marker (projector dtype); None: full white.
        prime_s: seconds each level is watched for when the black and marker levels are measured first.
        min_contrast: least marker-minus-black step, as a fraction of the camera's largest mean code seen, that
            counts as the marker being seen.
        progress: called as ``progress(try_index, tries, delay_s)`` after each try, or None.

    Returns:
        :class:`LatencyResult` (``settle_s`` None).

    Raises:
        RigError: the camera never saw the marker (or never saw black again) within ``timeout_s``, or a device
            fault.
    """
    if tries < 1:
        raise ValueError(f"tries must be >= 1, got {tries}")
    dtype = np.dtype(projector.dtype)
    black = np.zeros(projector.shape, dtype)
    if marker is None:
        marker = np.full(projector.shape, np.iinfo(dtype).max, dtype)
    step = "latency measurement"
    b, w, period = _levels(projector, camera, black, marker, timeout_s, prime_s, min_contrast, step)
    mid = 0.5 * (b + w)
    rng = np.random.default_rng(tries)
    delays: list[float] = []
    for i in range(tries):
        delays.append(_one_delay(projector, camera, black, marker, (b, mid, w), period, rng, timeout_s, step))
        if progress is not None:
            progress(i, tries, delays[-1])
    projector.show(black, step=step)
    a = np.asarray(delays)
    return LatencyResult(median_s=float(np.median(a)), max_s=float(a.max()), samples=tuple(float(x) for x in a),
                         black_level=b, marker_level=w, frame_s=period)


def calibrate_latency(rig_file: str | Path, tries: int = 20, *, timeout_s: float = 2.0, margin: float = 0.25,
                      min_margin_s: float = 0.02, operator: Callable[[str], None] | None = None,
                      progress: Callable[[int, int, float], None] | None = None, projector=None,
                      camera=None) -> LatencyResult:
    """Measure the projector-to-LF-camera latency and write ``projector.settle_s`` into the rig file.

    Args:
        rig_file: the rig file; its ``projector`` and ``lf_camera`` are opened (unless given below), and its
            ``projector.settle_s`` is replaced (:func:`~.config.write_rig_value`: every other line kept).
        tries: delays measured.
        timeout_s: longest wait for the camera to see one change, seconds.
        margin, min_margin_s: settle_s = max + max(min_margin_s, margin * max), rounded up to 1 ms
            (:func:`settle_time`).
        operator: where given, first asked for the focal-plane diffuser set-up (so the LF camera sees the
            projector) and waited for; None: the caller has arranged it. A rig file whose ``[operator]`` names an
            endpoint gets the set-up there instead, and the real scene again afterwards.
        progress: ``progress(try_index, tries, delay_s)`` after each try, or None.
        projector, camera: open devices to use instead of the rig file's (they are not closed here).

    Returns:
        :class:`LatencyResult` with ``settle_s`` the value written.

    Raises:
        RigFileError: an invalid rig file.
        RigError: a device fault, or the camera never saw the marker.
    """
    from lftransfer.rig.hardware.cameras import open_camera
    from lftransfer.rig.hardware.config import load_rig_file, write_rig_value
    from lftransfer.rig.hardware.projector import ProjectorWindow

    config = load_rig_file(rig_file)
    own: list = []
    try:
        if projector is None:
            projector = ProjectorWindow(config.projector)
            own.append(projector)
        if camera is None:
            camera = open_camera(config.lf_camera, "LF camera")
            own.append(camera)
        arrange, endpoint = arranger(config.operator, operator or (lambda prompt: None))
        if operator is not None or endpoint:
            arrange(FocalPlaneDiffuser())
        result = measure_latency(projector, camera, tries, timeout_s=timeout_s, progress=progress)
        if endpoint:
            arrange(RealScene())          # as a run expects to find the rig
    finally:
        for device in reversed(own):
            device.close()
    settle = settle_time(result, margin, min_margin_s)
    write_rig_value(rig_file, "projector.settle_s", settle)
    _log.info("latency: median %.3f s, max %.3f s; settle_s = %.3f written to %s", result.median_s,
              result.max_s, settle, rig_file)
    return replace(result, settle_s=settle)

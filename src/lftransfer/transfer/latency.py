"""Motion-to-composite latency of the live loop: what a person moving an object feels.

A change of the synthetic scene (an object moved by its animation, an edit from the page) at time t gets a new
version of the synthetic scene (:attr:`lftransfer.transfer.live.LiveTransfer.changes`). Two moments follow:

- **view**: the first composite that shows the synthetic objects as changed (its ``scene_version`` reaches the
  change's): the render after the change;
- **light**: the first composite whose real objects' light reflects the change (its ``light_version`` reaches it):
  the synthetic light field rendered after the change was projected, captured, decoded and rendered with.

Each latency is that composite's ready time minus t. A change that a later one overtook before any frame showed it
counts as shown by the frame that shows the later one (a person sees the newest state at once).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Sequence

import numpy as np

__all__ = ["LatencySpread", "MotionLatency", "motion_latency"]


@dataclass(frozen=True)
class LatencySpread:
    """Milliseconds over the changes that were shown: median, 95th percentile, largest, and how many."""

    median: float
    p95: float
    max: float
    count: int

    @classmethod
    def of(cls, seconds: np.ndarray) -> "LatencySpread | None":
        if len(seconds) == 0:
            return None
        ms = 1000.0 * np.asarray(seconds, float)
        return cls(round(float(np.median(ms)), 1), round(float(np.percentile(ms, 95)), 1),
                   round(float(ms.max()), 1), int(len(ms)))


@dataclass(frozen=True)
class MotionLatency:
    """Motion-to-composite latency over a run of the live loop.

    Attributes:
        view: latency until the composite shows the change (None: no change was shown).
        light: latency until the real objects' light in the composite reflects it (None: none reached).
        changes: changes of the synthetic scene in the run.
        pending_view, pending_light: changes no frame had shown (its light) by the end of the run.
        loop: "sync" or "decoupled".
    """

    view: LatencySpread | None
    light: LatencySpread | None
    changes: int
    pending_view: int
    pending_light: int
    loop: str

    def to_json(self) -> dict:
        return asdict(self)


def _first_reaching(versions: np.ndarray, ready: np.ndarray, wanted: np.ndarray) -> np.ndarray:
    """Ready time of the first frame whose version is at least each wanted version (NaN: none).

    Args:
        versions: (F,) the frames' versions, in frame order.
        ready: (F,) their ready times, seconds.
        wanted: (C,) versions.
    """
    if len(versions) == 0:
        return np.full(len(wanted), np.nan)
    reached = np.maximum.accumulate(versions)                 # the newest version shown by each frame so far
    first = np.searchsorted(reached, wanted, side="left")     # the first frame where it reaches the wanted one
    out = np.full(len(wanted), np.nan)
    ok = first < len(reached)
    out[ok] = ready[first[ok]]
    return out


def motion_latency(changes: Sequence[tuple[int, float]], frames: Sequence, loop: str) -> MotionLatency:
    """Latency of each change in ``changes`` until the frames showed it.

    Args:
        changes: (version, ``time.perf_counter()`` seconds) of each change, in order
            (:attr:`LiveTransfer.changes <lftransfer.transfer.live.LiveTransfer.changes>`).
        frames: the loop's frames (:class:`~lftransfer.transfer.live.LiveFrame`, in order): their
            ``scene_version``, ``light_version`` and ``ready_s``.
        loop: the loop they came from.
    """
    frames = sorted(frames, key=lambda f: f.ready_s)
    ready = np.array([f.ready_s for f in frames], float)
    start = frames[0].started_s if frames else 0.0
    # changes before the first frame began (the scene as it was set up) are not motion a person made
    kept = [(v, t) for v, t in changes if t >= start]
    wanted = np.array([v for v, _ in kept], float)
    at = np.array([t for _, t in kept], float)
    view = _first_reaching(np.array([f.scene_version for f in frames], float), ready, wanted) - at
    light = _first_reaching(np.array([f.light_version for f in frames], float), ready, wanted) - at
    return MotionLatency(view=LatencySpread.of(view[np.isfinite(view)]),
                         light=LatencySpread.of(light[np.isfinite(light)]), changes=len(kept),
                         pending_view=int(np.sum(~np.isfinite(view))), pending_light=int(np.sum(~np.isfinite(light))),
                         loop=loop)

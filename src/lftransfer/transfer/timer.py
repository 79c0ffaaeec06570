"""Wall-clock time per stage of a transfer (capture, decode, render, ...), rates, and the cores each side keeps
busy."""

from __future__ import annotations

import os
import time
from collections import deque
from contextlib import contextmanager
from typing import Callable, Sequence

__all__ = ["CoreMeter", "StageTimer", "rate_hz"]


class StageTimer:
    """Adds up seconds per stage name: ``with timer("capture"): ...``.

    Attributes:
        totals: stage -> seconds so far.
    """

    def __init__(self) -> None:
        self.totals: dict[str, float] = {}

    @contextmanager
    def __call__(self, stage: str):
        t0 = time.perf_counter()
        try:
            yield
        finally:
            self.totals[stage] = self.totals.get(stage, 0.0) + time.perf_counter() - t0


def rate_hz(times: Sequence[float], last: int = 8) -> float:
    """Events per second over the last ``last`` intervals between ``time.perf_counter()`` moments (0 before two)."""
    recent = list(times)[-(last + 1):]
    return (len(recent) - 1) / (recent[-1] - recent[0]) if len(recent) > 1 and recent[-1] > recent[0] else 0.0


class CoreMeter:
    """The cores a live loop keeps busy, and those a simulator process beside it does, over the last few seconds.

    Each :meth:`sample` notes this process's CPU seconds (``time.process_time()``: every thread of it) and the
    other process's (``other()``), and returns each side's CPU seconds per wall-clock second since the oldest note
    within ``window_s``.

    Args:
        other: the CPU seconds a second process has used so far (the simulator's,
            :meth:`lftransfer.sim.process.SimulatorProcess.cpu_seconds`), or None where there is none.
        window_s: seconds the rates are taken over.
    """

    def __init__(self, other: Callable[[], float | None] | None = None, window_s: float = 2.0) -> None:
        self.other, self.window_s = other, float(window_s)
        self.cores = os.cpu_count() or 1
        self._notes: deque[tuple[float, float, float | None]] = deque()

    def sample(self) -> dict:
        """``{"loop": cores busy, "simulator": cores busy or None, "cores": the machine's cores}`` (the busy cores
        0.0 before two notes)."""
        now = (time.perf_counter(), time.process_time(), self.other() if self.other is not None else None)
        self._notes.append(now)
        while len(self._notes) > 2 and now[0] - self._notes[1][0] >= self.window_s:
            self._notes.popleft()
        first = self._notes[0]
        wall = now[0] - first[0]
        loop = (now[1] - first[1]) / wall if wall > 0 else 0.0
        sim = None if now[2] is None or first[2] is None else (now[2] - first[2]) / wall if wall > 0 else 0.0
        return {"loop": round(loop, 2), "simulator": None if sim is None else round(sim, 2), "cores": self.cores}

"""Wall-clock time per stage of a transfer (capture, decode, render, ...)."""

from __future__ import annotations

import time
from contextlib import contextmanager
from typing import Sequence

__all__ = ["StageTimer", "rate_hz"]


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

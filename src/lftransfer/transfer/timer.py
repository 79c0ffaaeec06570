"""Wall-clock time per stage of a transfer (capture, decode, render, ...)."""

from __future__ import annotations

import time
from contextlib import contextmanager

__all__ = ["StageTimer"]


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

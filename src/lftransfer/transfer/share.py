"""The machine shared in turns between the renderer and a capture process beside it (docs/performance.md, "The
simulator beside the renderer").

On the simulated rig a capture is a path-traced render in a process of its own
(:class:`lftransfer.sim.process.SimulatorProcess`). Run at the same time as the renderer, even at a lower
priority, it slows every frame by more than the cores it takes: the two compete for the caches and the memory
bandwidth, which a priority does not share out. :class:`TurnTaking` gives each its turn instead. The capture
process is stopped while a frame renders, and before the next frame begins it runs alone for its share of the
time the last frame took:

    frame (capture process stopped) | capture process alone, share / (1 - share) of that frame | frame | ...

So the renderer keeps ``1 - share`` of its own rate while a capture is in progress, and the capture process has the
whole machine for the rest. When no capture is in progress (the captures held, the page paused) the frames do not
wait.
"""

from __future__ import annotations

import time
from contextlib import contextmanager
from typing import Callable, Iterator

__all__ = ["TurnTaking"]


class TurnTaking:
    """Frames and a capture process in turns.

    Args:
        pause: stops the capture process (it takes no core until ``resume``).
        resume: lets it go on.
        busy: whether it is working on a capture (its turn is only waited for then).
        share: the fraction of the wall-clock time the capture process gets while frames render one after another,
            strictly between 0 and 1.

    Attributes:
        waited_s: seconds the frames waited for the capture process's turns so far.
    """

    def __init__(self, pause: Callable[[], None], resume: Callable[[], None], busy: Callable[[], bool],
                 share: float) -> None:
        if not 0.0 < share < 1.0:
            raise ValueError(f"the capture process's share: expected a fraction strictly between 0 and 1, got {share}")
        self.pause, self.resume, self.busy, self.share = pause, resume, busy, float(share)
        self._owed_s = 0.0                  # the capture process's turn after the last frame, seconds
        self._since = time.perf_counter()   # when it was last let go on
        self.waited_s = 0.0

    @contextmanager
    def rendering(self) -> Iterator[None]:
        """Render a frame in the renderer's turn: first the capture process's turn (what is left of it, if a
        capture is in progress), then the capture process stopped until the frame is done."""
        left = self._owed_s - (time.perf_counter() - self._since)
        if left > 0 and self.busy():
            time.sleep(left)
            self.waited_s += left
        self.pause()
        start = time.perf_counter()
        try:
            yield
        finally:
            self._since = time.perf_counter()
            self.resume()
            self._owed_s = (self._since - start) * self.share / (1.0 - self.share)

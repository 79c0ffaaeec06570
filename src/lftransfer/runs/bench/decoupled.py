"""The decoupled live loop timed as ``lft live`` runs it (``lft bench --live``): captures on their own thread at
the simulated rig's rate, frames rendered as fast as the renderer goes with the newest capture, a synthetic object
moving every frame.

On the simulated rig the captures are the simulator's renders, so the simulator and the render loop share the
machine's cores: the frame rate measured here is lower than a physical rig's computer would give, whose cameras
expose on their own. It is what ``lft live`` on the simulated rig shows, with the simulator where ``lft live``
puts it (:class:`~lftransfer.settings.SimulatorSettings`: by default a process of its own at a lower priority,
:mod:`lftransfer.sim.process`). What it measures beside the rates is the latency a person feels
(:mod:`lftransfer.transfer.latency`): from each move to the first composite that shows it, and to the first whose
real objects' light reflects it.

In the same run it renders as many frames again with the captures held (the newest capture reused, the simulator
idle): the renderer alone. The ratio of the two rates is what the simulator capturing beside the renderer costs
the page, and the CPU time over each phase says how many cores each side kept busy.
"""

from __future__ import annotations

import math
import statistics
import time
from dataclasses import asdict, dataclass
from typing import Callable

import numpy as np

from lftransfer.settings import SimulatorSettings
from lftransfer.transfer.latency import motion_latency
from lftransfer.transfer.live import FrameTimes, LiveTransfer
from lftransfer.transfer.share import TurnTaking
from lftransfer.transfer.timer import CoreMeter

__all__ = ["DecoupledRun", "run_decoupled"]

WARMUP_FRAMES = 2          # frames not counted (the first measures the depth and waits for the first capture)
MAX_SECONDS = 900.0        # the run stops after this long even when it has fewer captures than asked


@dataclass(frozen=True)
class DecoupledRun:
    """The decoupled loop over a run of frames.

    Attributes:
        frames: frames counted (after :data:`WARMUP_FRAMES`).
        seconds: wall-clock over them.
        render_fps: frames delivered per second (frames / seconds): the page's rate.
        frame_ms: median milliseconds per frame (the step: render with the newest capture, composite).
        captures: captures the counted frames used.
        capture_hz: captures per second of the capture thread at the end.
        capture_age_s: median and largest seconds from a frame's capture to its composite.
        capture_behind_s: median and largest scene time between a frame and the real scene its capture saw.
        latency: motion-to-composite latency (:class:`~lftransfer.transfer.latency.MotionLatency` as JSON).
        stages_ms: median milliseconds per render-side stage.
        stages_ms_alone: the same with the captures held (the renderer alone).
        capture_stages_ms: median milliseconds per capture-side stage (encode, capture, decode, capture_view).
        render_fps_alone: frames per second over as many frames with the captures held (the simulator idle).
        rate_with_simulator: ``render_fps / render_fps_alone``: the share of the renderer's own rate the page
            keeps while the simulator captures beside it.
        cores_busy, cores_busy_alone: the loop's process's CPU seconds per wall-clock second (every thread, Dr.Jit's
            included) while capturing and with the captures held. With the simulator in this process their
            difference is at least what the simulator takes (the renderer, slowed beside it, takes less).
        simulator: where the simulator ran and its threads (:class:`~lftransfer.settings.SimulatorSettings` as JSON).
        simulator_cores_busy: the simulator process's CPU seconds per wall-clock second while capturing (None: it
            ran in the loop's process, counted in ``cores_busy``).
    """

    frames: int
    seconds: float
    render_fps: float
    frame_ms: float
    captures: int
    capture_hz: float
    capture_age_s: dict
    capture_behind_s: dict
    latency: dict
    stages_ms: dict
    capture_stages_ms: dict
    render_fps_alone: float
    rate_with_simulator: float
    cores_busy: float
    cores_busy_alone: float
    simulator: dict
    simulator_cores_busy: float | None = None
    stages_ms_alone: dict | None = None

    def to_json(self) -> dict:
        return asdict(self)


def _med_max(values) -> dict:
    values = list(values)
    return {"median": round(float(statistics.median(values)), 4), "max": round(float(max(values)), 4)}


def run_decoupled(rig, model, scene, settings, times: np.ndarray, *, frames: int, min_captures: int = 3,
                  simulator: SimulatorSettings = SimulatorSettings(where="thread"), turns: TurnTaking | None = None,
                  progress: Callable[[str], None] | None = None) -> DecoupledRun:
    """Run the decoupled loop over the scene times ``times`` (cycled) for at least ``frames`` counted frames and
    until the counted frames used ``min_captures`` captures and a change's light has reached one of them (or
    :data:`MAX_SECONDS` passed).

    Args:
        rig: the simulated rig (only this loop uses it meanwhile).
        model: the rig model.
        scene: the synthetic part of the scene (its animation moves the object).
        settings: the transfer settings.
        simulator: where the rig's simulator runs (reported; the rig was opened with it).
        turns: the frames' turns with the simulator process (:attr:`lftransfer.runs.rigs.OpenedRig.turns`), or None.
        times: (F,) scene times of the frames, seconds.
        frames: frames to count (>= 2).
        min_captures: distinct captures the counted frames must have used.
        progress: called with one message as it starts.
    """
    (progress or (lambda _m: None))(f"decoupled loop: {frames} frames and {min_captures} captures at least, then "
                                    "as many with the captures held")
    done = []
    child_cpu = getattr(rig, "cpu_seconds", None)     # the simulator process's CPU seconds, if it has one
    with LiveTransfer(rig, model, scene, settings, loop="decoupled", turns=turns) as live:
        start = time.perf_counter()
        i = 0
        while True:
            if i == WARMUP_FRAMES:                      # the counted frames' CPU time, from here to the end
                cores = CoreMeter(child_cpu, window_s=math.inf)
                cores.sample()
            frame = FrameTimes.of(live.step(float(times[i % len(times)])))
            i += 1
            if i > WARMUP_FRAMES:
                done.append(frame)
            captures = len({f.capture_index for f in done})
            # ... and until a change's light reached a frame (its latency measured), which needs a capture that
            # started after the change: with captures slower than frames that can take more than min_captures
            if len(done) >= frames and captures >= min_captures and (
                    not live.changes or motion_latency(list(live.changes), done, "decoupled").light is not None):
                break
            if time.perf_counter() - start > MAX_SECONDS and len(done) >= 2:
                break
        busy = cores.sample()
        capture_hz = live.capture_rate_hz or 0.0
        latency = motion_latency(list(live.changes), done, "decoupled")
        alone, cores_alone, alone_frames = _renderer_alone(live, times, i, len(done))
    seconds = done[-1].ready_s - done[0].started_s
    render = sorted({k for f in done for k in f.timings_s if k != "total"})
    captured = sorted({k for f in done for k in f.capture_timings_s})
    return DecoupledRun(
        frames=len(done), seconds=round(seconds, 3), render_fps=round(len(done) / seconds, 3),
        frame_ms=round(1000 * statistics.median(f.timings_s["total"] for f in done), 2),
        captures=len({f.capture_index for f in done}), capture_hz=round(capture_hz, 4),
        capture_age_s=_med_max(f.capture_age_s for f in done),
        # (a frame of a new cycle of the times is ahead of a capture from the last cycle's end: left out)
        capture_behind_s=_med_max([f.time_s - f.capture_time_s for f in done if f.time_s >= f.capture_time_s] or [0]),
        latency=latency.to_json(),
        stages_ms=_stage_medians(done, render), stages_ms_alone=_stage_medians(alone_frames, render),
        capture_stages_ms=_stage_medians(done, captured, "capture_timings_s"),
        render_fps_alone=round(alone, 3), rate_with_simulator=round(len(done) / seconds / alone, 3),
        cores_busy=busy["loop"], cores_busy_alone=cores_alone, simulator=simulator.to_json(),
        simulator_cores_busy=busy["simulator"])


def _stage_medians(frames, stages, times: str = "timings_s") -> dict:
    """Median milliseconds per stage over ``frames``, of their render stages (or of the field ``times`` names: their
    capture's, ``"capture_timings_s"``)."""
    return {k: round(1000 * statistics.median(getattr(f, times).get(k, 0.0) for f in frames), 2) for k in stages}


def _renderer_alone(live: LiveTransfer, times: np.ndarray, first: int, frames: int) -> tuple[float, float, list]:
    """(frames per second, cores busy, the frames) of ``frames`` frames rendered with the captures held, from time
    index ``first`` on: the capture in progress finishes first, then no new one begins."""
    with live.holding_rigs():                    # waits for the capture in progress; none begins meanwhile
        cores = CoreMeter(window_s=math.inf)
        cores.sample()
        start = time.perf_counter()
        done = [FrameTimes.of(live.step(float(times[i % len(times)]))) for i in range(first, first + frames)]
        wall = time.perf_counter() - start
        return frames / wall, cores.sample()["loop"], done

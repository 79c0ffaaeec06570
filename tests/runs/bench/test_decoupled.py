"""``lft bench --live``'s decoupled run: the render rate with the simulator capturing beside the renderer and, in the
same run, with the captures held (lftransfer.runs.bench.decoupled).

What each test shows: the run reports both rates, their ratio and the cores busy in each phase; while the renderer
runs alone no capture begins (at most the one in progress ends), though with the captures free the simulator
captured several over the same number of frames.
"""

from __future__ import annotations

import numpy as np

from lftransfer.runs.bench import decoupled
from lftransfer.transfer.live import FrameTimes
from lftransfer.runs.pipeline import RunOptions, open_rig
from lftransfer.scenes import builtin_scene, load_scene, quick_scene
from lftransfer.transfer.bounce import TransferSettings


class _CountingRig:
    """A rig that counts its LF captures."""

    def __init__(self, inner) -> None:
        self.inner, self.captures = inner, 0

    def __getattr__(self, name):
        return getattr(self.inner, name)

    def capture_lf(self, *args, **kwargs):
        self.captures += 1
        return self.inner.capture_lf(*args, **kwargs)


def test_01_the_renderer_alone_and_beside_the_simulator(variant, monkeypatch):
    scene = quick_scene(load_scene(builtin_scene("fig4")))
    settings = TransferSettings(angular_samples=scene.rig.angular_samples, bounces=1, bounce_views=False)
    opened = open_rig(scene, RunOptions(truth_seed=None))
    rig = _CountingRig(opened.rig)
    counts = []
    alone = decoupled._renderer_alone

    def counted(live, times, first, frames):
        counts.append(rig.captures)
        out = alone(live, times, first, frames)
        counts.append(rig.captures)
        return out

    monkeypatch.setattr(decoupled, "_renderer_alone", counted)
    run = decoupled.run_decoupled(rig, opened.oracle.model, scene.synthetic_part(), settings, np.zeros(1),
                                  frames=4, min_captures=3)
    assert run.captures >= 3 and run.render_fps > 0 and run.render_fps_alone > 0
    assert abs(run.rate_with_simulator - run.render_fps / run.render_fps_alone) < 0.01
    assert run.cores_busy > 0 and run.cores_busy_alone > 0
    assert counts[1] - counts[0] <= 1                  # held: no capture began (the one in progress may end)
    assert run.captures >= 3 > counts[1] - counts[0]   # ... while beside the frames the simulator captured
    assert set(run.stages_ms_alone) == set(run.stages_ms) and run.stages_ms_alone["render_lightfield"] > 0


def test_02_the_run_keeps_the_frames_times_not_their_images():
    """A few hundred frames at the paper's resolution held 19 GB when the run kept whole frames, and every frame
    rendered slower for it: what it keeps of a frame holds no array."""
    from types import SimpleNamespace

    fields = FrameTimes.__dataclass_fields__
    frame = SimpleNamespace(**{name: 1.0 for name in fields}, composite=np.zeros((512, 512, 3)),
                            synthetic_lf=np.zeros((8, 8, 8, 8, 3)))
    kept = FrameTimes.of(frame)
    assert not any(isinstance(getattr(kept, name), np.ndarray) for name in fields)
    assert not hasattr(kept, "composite") and not hasattr(kept, "synthetic_lf")

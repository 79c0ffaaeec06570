"""The live loop: one capture and one render per frame, bounces accumulating over frames (docs/architecture.md,
"The live loop")."""

from __future__ import annotations

import numpy as np
import pytest

from lftransfer.runs.pipeline import RunOptions, open_rig

from lftransfer.scenes import quick_scene
from lftransfer.scenes import builtin_scene, load_scene, with_overrides
from lftransfer.settings import SimulatorSettings
from lftransfer.transfer.bounce import TransferSettings, run_transfer
from lftransfer.transfer.live import LiveTransfer


def _rel(a, b) -> float:
    return float(np.linalg.norm(a - b) / np.linalg.norm(b))


@pytest.fixture(scope="module")
def quick(variant):
    scene = quick_scene(load_scene(builtin_scene("fig4")))
    return scene, TransferSettings(angular_samples=scene.rig.angular_samples, bounces=3, bounce_views=False)


def test_01_still_scene_converges_to_the_bounce_loop(quick):
    """Frame 0 sees the projector black (the direct frame); after a few frames the capture and the real view
    equal the bounce loop's with as many bounces (the exchange reaches the same fixed point)."""
    scene, settings = quick
    opened = open_rig(scene, RunOptions(truth_seed=None))
    reference = run_transfer(opened.rig, opened.oracle.model, scene.synthetic_part(), settings)
    live = LiveTransfer(opened.rig, opened.oracle.model, scene.synthetic_part(), settings)
    frames = [live.step(0.0) for _ in range(4)]
    direct = reference.bounces[0].real_lf.data
    assert not frames[0].projected_lf.data.any()
    np.testing.assert_allclose(frames[0].real_view, reference.real_view_direct, rtol=1e-5, atol=1e-7)
    # captures carry the simulated camera's noise (about 1 %); the bounces add about 2 % of the light
    assert _rel(frames[0].captured_lf.data, direct) < 0.02
    all_bounces = sum(b.real_lf.data for b in reference.bounces)
    assert _rel(frames[3].captured_lf.data, all_bounces) < 0.02                 # measured 0.9 %
    assert _rel(frames[3].real_view, reference.real_view) < 0.005               # measured 0.09 %
    # negative control: the direct frame is measurably away from the converged one
    assert _rel(frames[0].real_view, reference.real_view) > 0.01
    assert all(set(f.timings_s) >= {"capture", "decode", "render_lightfield", "render_view", "total"} for f in frames)
    live.reset()
    assert not live.step(0.0).projected_lf.data.any()


def test_02_moving_objects_move_on_both_sides(quick):
    """A keyframed synthetic object moves in the renderer and a keyframed real object in the simulated rig; the
    frames at the two times differ where they stand, and a still frame is repeated exactly."""
    scene, settings = quick
    real, syn = scene.real[0].model_dump(), scene.synthetic[0].model_dump()
    real["keyframes"] = [{"time_s": 0.0}, {"time_s": 1.0, "translate": [real["translate"][0] + 0.03, *real["translate"][1:]]}]
    syn["keyframes"] = [{"time_s": 0.0}, {"time_s": 1.0, "translate": [syn["translate"][0] - 0.03, *syn["translate"][1:]]}]
    moving = with_overrides(scene, animation={"duration_s": 1.0, "fps": 2}, real=[real], synthetic=[syn])
    opened = open_rig(moving, RunOptions(truth_seed=None))
    live = LiveTransfer(opened.rig, opened.oracle.model, moving.synthetic_part(), settings)
    a = live.step(0.0)
    b = live.step(1.0)
    assert b.moved and not a.moved
    assert _rel(b.synthetic_view.alpha, a.synthetic_view.alpha) > 0.1            # the synthetic cube moved
    direct_a, direct_b = a.captured_lf.data, b.captured_lf.data
    assert _rel(direct_b, direct_a) > 0.1                                        # the real block moved
    live.reset()
    again = live.step(0.0)
    np.testing.assert_array_equal(again.synthetic_view.alpha, a.synthetic_view.alpha)


def test_02b_depth_projection_is_measured_once_and_converges_to_the_bounce_loop(quick):
    """With ``projection = "depth"`` the first frame measures the real scene's depth (the bounce loop's own
    measurement gives the same map, up to the capture noise at the dark threshold), every frame prefilters, and a
    still scene converges to the bounce loop run with the same projection (measured: 0.11 % in the real view, as
    with the box light field)."""
    from dataclasses import replace

    scene, settings = quick
    settings = replace(settings, projection="depth")
    opened = open_rig(scene, RunOptions(truth_seed=None))
    reference = run_transfer(opened.rig, opened.oracle.model, scene.synthetic_part(), settings)
    live = LiveTransfer(opened.rig, opened.oracle.model, scene.synthetic_part(), settings)
    frames = [live.step(0.0) for _ in range(4)]
    assert "measure_depth" in frames[0].timings_s and not any("measure_depth" in f.timings_s for f in frames[1:])
    assert all("prefilter" in f.timings_s for f in frames)
    found, again = np.isfinite(reference.depth), np.isfinite(live.side.prefilter.depth)
    assert found.mean() > 0.05 and np.mean(found == again) > 0.99      # measured: 0.16 % of the entries differ
    both = found & again
    assert np.median(np.abs(live.side.prefilter.depth[both] - reference.depth[both])) < 1e-3
    assert _rel(frames[3].real_view, reference.real_view) < 0.005
    # a depth measured earlier is used as given, not measured again (a resumed sequence, the exchange check)
    given = run_transfer(opened.rig, opened.oracle.model, scene.synthetic_part(), settings, depth=live.depth)
    assert "measure_depth" not in given.timings_s and given.depth is live.depth
    assert _rel(given.real_view, reference.real_view) < 0.005
    again = LiveTransfer(opened.rig, opened.oracle.model, scene.synthetic_part(), settings, depth=live.depth)
    assert again.depth is live.depth and "measure_depth" not in again.step(0.0).timings_s
    box = run_transfer(opened.rig, opened.oracle.model, scene.synthetic_part(), replace(settings, projection="box"),
                       depth=live.depth)
    assert box.depth is None and "prefilter" not in box.timings_s         # nothing prefilters: the depth is unused


def test_03_fig5_the_sun_lights_the_head_through_the_projector(variant):
    """The paper's Fig. 5 scene has no real light: at the first live frame (projector black) the head is dark;
    from the second on, the synthetic sun's light, sent by the projector, lights it; the sun is seen at its own
    radiance and the planet's side towards the sun is lit."""
    scene = quick_scene(load_scene(builtin_scene("fig5")))
    assert not scene.lights and scene.moving
    opened = open_rig(scene, RunOptions(truth_seed=None))
    settings = TransferSettings(angular_samples=scene.rig.angular_samples)
    live = LiveTransfer(opened.rig, opened.oracle.model, scene.synthetic_part(), settings)
    dark = live.step(4.0)
    lit = live.step(4.0)
    assert float(dark.real_view.max()) == 0.0
    head = lit.real_view.sum(axis=2) > 0
    assert head.mean() > 0.02 and float(np.median(lit.real_view[head].sum(axis=1))) > 0.01
    sun = max(o.material.radiance[0] for o in scene.synthetic if o.material.type == "emitter")
    assert float(lit.synthetic_view.rgb[..., 0].max()) == pytest.approx(sun, rel=1e-4)
    assert lit.clipped_fraction == 0.0


class _SlowRig:
    """A rig whose LF camera takes ``delay_s`` longer per capture (a slow device), or fails after ``fail_after``
    captures; everything else is the wrapped rig's."""

    def __init__(self, rig, delay_s: float = 0.0, fail_after: int | None = None) -> None:
        self.inner, self.delay_s, self.fail_after, self.captures = rig, delay_s, fail_after, 0

    def __getattr__(self, name):
        return getattr(self.inner, name)

    def capture_lf(self, *args, **kwargs):
        import time

        if self.fail_after is not None and self.captures >= self.fail_after:
            raise OSError("the LF camera went away")
        time.sleep(self.delay_s)
        self.captures += 1
        return self.inner.capture_lf(*args, **kwargs)


@pytest.mark.parametrize("where", ["thread", "process"])
def test_04_decoupled_loop_converges_to_the_same_light(quick, where):
    """Captures on their own thread, each under the newest light field rendered: after a few captures the real
    view is the bounce loop's (as the synchronous loop's is, test_01); frames that found no new capture reuse the
    newest one and say how old it is. The same with the simulated rig in a process of its own (``lft live``'s
    default), taking turns with the frames (``--simulator-share``), against the bounce loop run in process."""
    scene, settings = quick
    opened = open_rig(scene, RunOptions(truth_seed=None))
    reference = run_transfer(opened.rig, opened.oracle.model, scene.synthetic_part(), settings)
    if where == "process":
        opened = open_rig(scene, RunOptions(truth_seed=None),
                          simulator=SimulatorSettings(where="process", threads=2, share=0.25))
        assert type(opened.rig).__name__ == "SimulatorProcess" and opened.turns.share == 0.25
    with LiveTransfer(opened.rig, opened.oracle.model, scene.synthetic_part(), settings, loop="decoupled",
                      turns=opened.turns) as live:
        frames = [live.step(0.0)]
        while frames[-1].capture_index < 6:
            frames.append(live.step(0.0))
        assert live.capture_rate_hz > 0
    opened.rig.close()
    if where == "process":
        assert opened.turns.waited_s > 0                     # the frames gave the simulator its turns
    assert all(f.loop == "decoupled" and "capture" not in f.timings_s for f in frames)
    assert all(set(f.capture_timings_s) == {"encode", "capture", "decode", "capture_view"} for f in frames)
    assert not frames[0].projected_lf.data.any() and frames[0].light_version == -1
    ages = np.array([f.capture_age_s for f in frames])
    assert np.all(ages > 0) and np.all(np.diff([f.capture_index for f in frames]) >= 0)
    assert _rel(frames[-1].real_view, reference.real_view) < 0.005               # as the synchronous loop's
    assert _rel(frames[0].real_view, reference.real_view) > 0.01                 # negative control: direct only


def test_05_an_edit_shows_in_the_next_frame_whatever_the_capture_rate(quick):
    """With an LF camera far slower than the renderer, a moved synthetic object is in the very next composite
    (same capture), and its light reaches the real objects' capture later; the latency says both."""
    from lftransfer.transfer.latency import motion_latency

    scene, settings = quick
    opened = open_rig(scene, RunOptions(truth_seed=None))
    slow = _SlowRig(opened.rig, delay_s=1.0)
    with LiveTransfer(slow, opened.oracle.model, scene.synthetic_part(), settings, loop="decoupled") as live:
        before = live.step(0.0)
        syn = scene.synthetic[0].model_dump()
        syn["translate"] = [syn["translate"][0], syn["translate"][1] + 0.03, syn["translate"][2]]
        live.set_scene(with_overrides(scene, synthetic=[syn]).synthetic_part())
        after = live.step(0.0)
        assert after.capture_index == before.capture_index                      # no new capture yet
        assert after.scene_version == before.scene_version + 1 > after.light_version
        assert _rel(after.synthetic_view.alpha, before.synthetic_view.alpha) > 0.1   # the object moved at once
        frames = [before, after]
        while frames[-1].light_version < after.scene_version:
            frames.append(live.step(0.0))
            assert len(frames) < 400
        # while it waited for the captures, the loop did not render frames with nothing new
        assert not live.has_news(0.0) or live._worker.newest().index != frames[-1].capture_index
    lat = motion_latency(live.changes, frames, "decoupled")
    assert lat.changes == 1 and lat.pending_view == lat.pending_light == 0
    assert lat.view.median < 1000.0 * (after.ready_s - after.started_s) + 1.0     # the frame after the edit
    # the light waits for a capture that began after the new light field was handed over: at least one capture
    assert lat.light.median > 1000.0 * slow.delay_s > lat.view.median


def test_06_decoupled_worker_failure_and_holding_the_rig(quick):
    """A capture that fails stops the worker and the next step raises with the device's message; holding the rig
    keeps new captures back."""
    import time

    scene, settings = quick
    opened = open_rig(scene, RunOptions(truth_seed=None))
    with LiveTransfer(_SlowRig(opened.rig, delay_s=0.2), opened.oracle.model, scene.synthetic_part(), settings,
                      loop="decoupled") as live:
        live.step(0.0)
        with live.holding_rigs():
            count = live._worker.count
            time.sleep(0.6)
            assert live._worker.count <= count + 1           # at most the capture in progress finished
        assert live._worker.wait(after=count + 1, timeout=60).index > count + 1       # captures went on
    failing = _SlowRig(opened.rig, fail_after=2)
    with LiveTransfer(failing, opened.oracle.model, scene.synthetic_part(), settings, loop="decoupled") as live:
        with pytest.raises(RuntimeError, match="LF camera went away"):
            for _ in range(200):
                live.step(0.0)
                time.sleep(0.05)


def test_06b_a_simulator_that_dies_stops_the_loop_in_one_line(quick):
    """The simulated rig in its own process, killed while the decoupled loop runs: the next steps raise one
    RigError that names the simulator process, its pid and how it ended; leaving the loop and closing the rig raise
    nothing more."""
    import os
    import signal
    import time

    from lftransfer.rig.base import RigError

    scene, settings = quick
    opened = open_rig(scene, RunOptions(truth_seed=None), simulator=SimulatorSettings(where="process"))
    pid = opened.rig.pid
    with LiveTransfer(opened.rig, opened.oracle.model, scene.synthetic_part(), settings, loop="decoupled") as live:
        live.step(0.0)
        os.kill(pid, signal.SIGKILL)
        with pytest.raises(RigError) as raised:
            for _ in range(400):
                live.step(0.0)
                time.sleep(0.05)
    message = str(raised.value)
    assert "\n" not in message
    assert f"the simulator process (pid {pid}) died (exit code -9)" in message
    opened.rig.close()
    opened.rig.close()                                   # idempotent on a dead simulator


def test_07_motion_latency_on_known_frames():
    """Latencies from known frame times: the view at the first frame that shows the version, the light at the
    first whose capture was lit by it; an overtaken change counts from its own time; an unshown one is pending."""
    from types import SimpleNamespace as F

    from lftransfer.transfer.latency import motion_latency

    frames = [F(started_s=0.0, ready_s=0.1, scene_version=0, light_version=-1),
              F(started_s=0.1, ready_s=0.2, scene_version=1, light_version=-1),
              F(started_s=0.2, ready_s=0.3, scene_version=3, light_version=0),
              F(started_s=0.3, ready_s=0.4, scene_version=3, light_version=1),
              F(started_s=0.4, ready_s=0.5, scene_version=3, light_version=3)]
    changes = [(1, 0.05), (2, 0.15), (3, 0.18), (4, 0.45)]
    lat = motion_latency(changes, frames, "decoupled")
    assert lat.changes == 4 and lat.pending_view == 1 and lat.pending_light == 1
    # view: 0.2 - 0.05, 0.3 - 0.15, 0.3 - 0.18; light: 0.4 - 0.05, 0.5 - 0.15, 0.5 - 0.18
    assert lat.view.count == 3 and lat.view.max == pytest.approx(150.0)
    assert lat.view.median == pytest.approx(150.0)
    assert lat.light.median == pytest.approx(350.0) and lat.light.max == pytest.approx(350.0)
    assert motion_latency([], frames, "sync").view is None

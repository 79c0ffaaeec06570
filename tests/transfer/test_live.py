"""The live loop: one capture and one render per frame, bounces accumulating over frames (docs/architecture.md,
"The live loop")."""

from __future__ import annotations

import numpy as np
import pytest

from lftransfer.app.pipeline import RunOptions, open_rig, quick_scene
from lftransfer.scenes import builtin_scene, load_scene, with_overrides
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

"""The composite a run chooses (``[render] composite``, ``--composite over|depth``): the depth composite measures
the real scene's depth even where the projection does not need it, carries it into the view camera, and on a scene
without occlusion (Fig. 4: the view camera in the array's plane, each half-space on its own side of the image)
gives the over operator's frame, in the bounce loop (which measures structured light too) and in the live loop
(which measures the LF camera's depth once, or at every step where the real objects move)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from lftransfer.runs.pipeline import RunOptions, open_rig

from lftransfer.scenes import quick_scene
from lftransfer.composite import composite
from lftransfer.scenes import builtin_scene, load_scene
from lftransfer.settings import Overrides, resolve_settings
from lftransfer.transfer.bounce import run_transfer
from lftransfer.transfer.live import LiveTransfer


def test_01_depth_composite_without_occlusion_is_the_over_operator(variant):
    from lftransfer.sim.metrics import depth_errors

    scene = quick_scene(load_scene(builtin_scene("fig4")))
    settings = resolve_settings(scene, Overrides(bounces=1, composite="depth", projection="box")).transfer
    assert settings.composite == "depth" and not settings.prefilters and settings.measures_depth
    opened = open_rig(scene, RunOptions(truth_seed=None))
    model, synthetic = opened.oracle.model, scene.synthetic_part()
    result = run_transfer(opened.rig, model, synthetic, replace(settings, bounce_views=False))
    vd = result.view_depth
    assert result.depth is not None and vd is not None and vd.known.any()
    # the bounce loop measures both sources, structured light too, and uses the better per pixel
    assert [d.source for d in result.depth_sources] == ["lightfield", "structured_light"]
    assert vd.source == "lightfield+structured_light" and result.timings_s.get("structured_light", 0) > 0
    over = composite(result.synthetic_view.rgb, result.synthetic_view.alpha, result.real_view)
    np.testing.assert_allclose(result.composite(), over, rtol=0, atol=1e-6)
    # the depth it used sees the real objects where they are (the oracle's depth) within centimetres
    errors = depth_errors(vd, opened.oracle.real_view_depth())
    assert errors["coverage"] > 0.5 and errors["error_mm_median"] < 40
    # over: no depth carried, the same frame
    plain = run_transfer(opened.rig, model, synthetic, replace(settings, composite="over", bounce_views=False))
    assert plain.view_depth is None and plain.depth is None
    # the live loop: the depth measured at the first step, carried into the view, the same frame as over
    live = LiveTransfer(opened.rig, model, synthetic, settings)
    frame = live.step(0.0)
    assert live.depth is not None and live.view_depth is not None
    np.testing.assert_allclose(frame.composite, composite(frame.synthetic_view.rgb, frame.synthetic_view.alpha,
                                                          frame.real_view), rtol=0, atol=1e-6)
    assert live.step(0.1).timings_s.get("measure_depth", 0) == 0         # once: the real objects stand still
    live.close()
    # real objects that move: the depth measured again at every step (the LF camera's only)
    moving = LiveTransfer(opened.rig, model, synthetic, settings, depth_every_frame=True)
    steps = [moving.step(t) for t in (0.0, 0.1)]
    assert all(f.timings_s.get("measure_depth", 0) > 0 for f in steps) and moving.view_depth.source == "lightfield"
    moving.close()

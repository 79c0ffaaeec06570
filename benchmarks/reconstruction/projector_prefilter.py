"""A study of the projector's side: do the depth prefilter of the projected light field
(``[render] projection = "depth"``, :mod:`lftransfer.transfer.projection`) and the solve against the measured
surface (``"solve"``, :mod:`lftransfer.transfer.surface_solve`) make the irradiance a real surface receives closer
to what the synthetic scene would have sent it than the box light field does?

Each scene runs three times, projecting the box light field, the prefiltered one and the solved one (the depth
measured through the rig: the projector shows white, the LF camera captures, a plane sweep finds where
neighbouring lenslets agree), and prints ``cross_by_side`` as ``where_the_error_is.py`` does. Scenes: Fig. 4 and five scenes of this folder
(true rig model, truth seed 2, the linear reconstruction, 2 bounces); at quarter resolution (ground truth 8192
samples per pixel) or, with ``--full``, at the paper's (48 x 48 directions per lenslet, ground truth 512).

``--fig5`` measures instead the planet's shadow on the head in Fig. 5 (converged 2-bounce transfers, true rig
model, truth seed 0; quarter resolution at frames 18, 30 and 42, or with ``--full`` the paper's resolution at
frames 24 and 42 with a ground truth of 128 samples per pixel) beside the ground truth's
(:mod:`lftransfer.sim.effects`): the projector carries the sun's light to the head, so the shadow's edge is
where the aperture's blur shows. It projects the box light field, the prefilter with 4 rays per entry and the
prefilter with the scene's ``lf_spp`` (16).

Run: python benchmarks/reconstruction/projector_prefilter.py [--fig5] [--full]   (20 s at quarter resolution
once the ground truths are cached, 3 minutes with --full; --fig5 2 minutes, --fig5 --full about 18). The tables are in
docs/architecture.md ("The projector's side").
"""

from __future__ import annotations

import sys
from dataclasses import replace

from lftransfer.runs.bench.step import transfer_settings
from lftransfer.runs.pipeline import RunOptions, knowledge, open_rig
from lftransfer.scenes import quick_scene
from lftransfer.scenes import builtin_scene, load_scene, with_overrides
from lftransfer.sim.ground_truth import render_ground_truth
from lftransfer.sim.metrics import evaluate
from lftransfer.transfer.bounce import run_transfer
from study_scenes import GT_SPP, by_side_cells, study_scenes
VARIANTS = ("box", "depth", "solve")


def transfer(opened, known, settings, variant: str, time_s: float = 0.0, synthetic=None, lf_spp=None):
    """One converged transfer projecting the variant's light field ("box", "depth" or "solve"), with ``lf_spp`` rays per
    light field entry (None: the settings')."""
    synthetic = known.scene if synthetic is None else synthetic
    settings = replace(settings, projection=variant, lf_spp=lf_spp or settings.lf_spp)
    return run_transfer(opened.rig, known.model, synthetic, settings, time_s=time_s)


def fig5_shadow(full: bool) -> None:
    from lftransfer.runs.effects import _without
    from lftransfer.composite import composite
    from lftransfer.sim.effects import measure_effect, object_distance, object_pixels

    scene = load_scene(builtin_scene("fig5"))
    scene = with_overrides(scene, render={"gt_spp": 128}) if full else quick_scene(scene)
    effect = scene.effect
    print("| frame | planet to head (m) | projected light field | contrast | penumbra (mm) | area taking half the "
          "light (cm^2) |")
    print("|---|---|---|---|---|---|")
    for frame in (24, 42) if full else (18, 30, 42):
        opened = open_rig(scene, RunOptions(truth_seed=0))
        known = knowledge(opened, scene, "oracle")
        t = frame / scene.animation.fps
        world = opened.oracle.world.at(t)
        pixels = object_pixels(world, effect.on)
        distance = object_distance(world, effect.on, effect.by)
        gt = render_ground_truth(world, spp=scene.render.gt_spp).image
        gt_without = render_ground_truth(_without(world, effect.by), spp=scene.render.gt_spp).image
        rows = [("ground truth", measure_effect("shadow", gt, gt_without, pixels))]
        settings = replace(transfer_settings(scene), bounces=2, bounce_views=False)
        for variant, spp in (("box", 4), ("depth", 4), ("depth", settings.lf_spp)):
            images = []
            for synthetic in (known.scene, _without(known.scene, effect.by)):
                opened.start_frame(frame)
                r = transfer(opened, known, settings, variant, t, synthetic, lf_spp=spp)
                images.append(composite(r.synthetic_view.rgb, r.synthetic_view.alpha, r.real_view))
            rows.append((f"{variant}, {spp} rays per entry", measure_effect("shadow", images[0], images[1], pixels)))
        for name, m in rows:
            pen = f"{1e3 * m.penumbra_m:.1f}" if m.penumbra_m is not None else "-"
            print(f"| {frame} | {distance:.3f} | {name} | {m.contrast:.3f} | {pen} | {1e4 * m.area_m2:.1f} |",
                  flush=True)


def cross_table(full: bool) -> None:
    print("| scene | projected light field | cross error | real side: error, energy ratio, error after best scale "
          "| synthetic side: the same | ground truth's noise (real) |")
    print("|---|---|---|---|---|---|")
    for name, scene in study_scenes(full):
        for variant in VARIANTS:
            opened = open_rig(scene, RunOptions(truth_seed=2))
            known = knowledge(opened, scene, "oracle")
            settings = replace(transfer_settings(scene), bounces=2, reconstruction="linear")
            opened.start_frame(0)
            result = transfer(opened, known, settings, variant)
            m = evaluate(result, opened.oracle.ground_truth(spp=512 if full else GT_SPP))
            print(f"| {name} | {variant} | {m.cross_transfer_rel_error:.3f} {by_side_cells(m, 'real')}", flush=True)


if __name__ == "__main__":
    full = "--full" in sys.argv[1:]
    fig5_shadow(full) if "--fig5" in sys.argv[1:] else cross_table(full)

"""The fast path against the exact path on the paper's glossy scenes (Figs. 6 and 1b), both against ground truth.

Each scene has two reflecting synthetic objects (a photograph on its frame: a glossy frame in fig6, a gold metal
frame and a glossy-coated photograph in fig1b). For each chosen frame the same rig (simulated, truth seed 0), the
same rig model (a calibration file) and the same settings (the scene's own: area model, linear reconstruction,
4 rays per sample, 2 bounces) run one converged transfer with each renderer; the frame's ground truth (path
traced, cached) scores both. Printed per scene and frame:

- ``render ms``: one synthetic render (relight, light field and view), the mean of the transfer's three (direct
  light and two bounces, each with its own primary rays), and the speed-up, exact over fast;
- ``live ms``: the same render in the live loop (``LiveTransfer.step``, frames up to the chosen one, the median
  of the last 3: the objects move every frame, the primary rays stay), and its speed-up;
- ``psnr_objects_db`` over the pixels the objects cover, and ``psnr_synthetic_db`` over the synthetic objects'
  pixels only (where the renderers differ), both with the ground truth's peak;
- the cross-transfer error and its synthetic side (``cross_by_side``), and the ground truth's own noise on it.

With ``--seeds A B ...`` the converged transfers are repeated with each render seed (the live timing is taken at
the first): the spread of each renderer's figures over the seeds is its own Monte Carlo noise on them.

Run: python benchmarks/glossy/fast_vs_exact.py [--quick] [--calibration FILE] [--frames 24 36] [--gt-spp N]
[--seeds 0 1]
(paper resolution with out/fullcal/calibration.json from ``lft calibrate fig4 --out out/fullcal/calibration.json``:
about 8 minutes when the ground truths are cached by an earlier ``lft render fig6|fig1b --verify-every 12
--gt-spp 128``; --quick: quarter resolution with the oracle rig model, about 1 minute).
"""

from __future__ import annotations

import argparse
from dataclasses import replace

import numpy as np

from lftransfer.runs.bench.step import transfer_settings
from lftransfer.runs.pipeline import RunOptions, knowledge, open_rig
from lftransfer.scenes import quick_scene
from lftransfer.runs.sequence import converged_frame, frame_ground_truth
from lftransfer.calibration.rig import load_calibration
from lftransfer.scenes import builtin_scene, load_scene
from lftransfer.sim.metrics import downsample, evaluate, metric_factor, psnr
from lftransfer.transfer.live import LiveTransfer


def synthetic_psnr(result, gt) -> float:
    """PSNR of the composite over the pixels the synthetic objects cover (ground truth's peak), dB."""
    from lftransfer.composite import composite

    f = metric_factor(result.real_view.shape[1])
    image = composite(result.synthetic_view.rgb, result.synthetic_view.alpha, result.real_view)
    ref = downsample(gt.image, f)
    mask = downsample(gt.alpha_synthetic, f) > 0.5
    return psnr(downsample(image, f), ref, float(ref.max()), mask=mask)


def live_render_ms(opened, known, settings, scene, frame: int, frames: int = 5) -> float:
    """The live loop's synthetic render (relight, light field, view) in ms: the median of the last 3 of ``frames``
    live steps ending at ``frame`` (the first two build the primary rays and their tiles)."""
    opened.start_frame(frame)
    live = LiveTransfer(opened.rig, known.model, known.scene, settings)
    fps = scene.animation.fps
    renders = []
    for i in range(frame - frames + 1, frame + 1):
        timings = live.step(i / fps).timings_s
        renders.append(1000 * (timings["render_lightfield"] + timings["render_view"]))
    return float(np.median(renders[2:]))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="quarter resolution, oracle rig model")
    parser.add_argument("--calibration", default="out/fullcal/calibration.json")
    parser.add_argument("--frames", type=int, nargs="+", default=[24, 36])
    parser.add_argument("--gt-spp", type=int, default=128)
    parser.add_argument("--scenes", nargs="+", default=["fig6", "fig1b"])
    parser.add_argument("--seeds", type=int, nargs="+", default=[0], help="render seeds of the converged runs")
    args = parser.parse_args()
    print("| scene, frame | renderer | seed | render ms (speed-up) | live ms (speed-up) | psnr_objects_db "
          "| psnr_synthetic_db | cross error | synthetic side | ground truth's noise on the cross term |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for name in args.scenes:
        scene = load_scene(builtin_scene(name))
        if args.quick:
            scene = quick_scene(scene)
        opened = open_rig(scene, RunOptions(truth_seed=0))
        if args.quick:
            known = knowledge(opened, scene, "oracle")
        else:
            known = knowledge(opened, scene, "calibrated",
                              calibration=load_calibration(args.calibration, scene.synthetic_part()))
        for frame in args.frames:
            t = frame / scene.animation.fps
            gt, _ = frame_ground_truth(opened.oracle, t, args.gt_spp, use_cache=True)
            times, live = {}, {}
            for seed in args.seeds:
                for renderer in ("fast", "exact"):
                    settings = replace(transfer_settings(scene), bounces=2, renderer=renderer, seed=seed)
                    result, _ = converged_frame(opened, known.model, known.scene, settings, frame, t)
                    ms = 1000 * sum(result.timings_s.get(k, 0.0) for k in ("render_lightfield", "render_view")) / 3
                    times.setdefault(renderer, ms)
                    if renderer not in live:
                        live[renderer] = live_render_ms(opened, known, settings, scene, frame)
                    m = evaluate(result, gt)
                    syn = m.cross_by_side["synthetic"]
                    speed = f" ({times['exact'] / times['fast']:.1f}x)" if renderer == "exact" else ""
                    live_speed = f" ({live['exact'] / live['fast']:.1f}x)" if renderer == "exact" else ""
                    timing = f"{ms:.0f}{speed} | {live[renderer]:.0f}{live_speed}" if seed == args.seeds[0] else "|"
                    print(f"| {name}, {frame} | {renderer} | {seed} | {timing} "
                          f"| {m.psnr_objects_db:.2f} | {synthetic_psnr(result, gt):.2f} "
                          f"| {m.cross_transfer_rel_error:.3f} | {syn.rel_error:.3f} | {m.cross_gt_noise_rel:.3f} |",
                          flush=True)
        opened.rig.close()


if __name__ == "__main__":
    main()

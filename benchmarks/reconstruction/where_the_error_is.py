"""Where Fig. 4's cross-transfer error comes from: the error split by side (``cross_by_side``) for the scene as
shipped and for rigs that differ in one respect only.

Variants (quarter resolution, the true rig model so that calibration error is left out, truth seed 1, the linear
reconstruction, 2 bounces, ground truth 8192 samples per pixel, shared by every variant since the ground truth
has no lens array):

- ``as shipped``: the paper's lens array, 25.4 mm pitch, f = 25.4 mm (a window of +-26.6 degrees);
- ``half pitch``: 12.7 mm lenslets (20 x 24 of them, the same extent), f = 12.7 mm (the same window), the LF
  camera and the projector with twice the pixels across (the same pixels per lenslet);
- ``wide window``: the same lenslets with f = 12.7 mm, a window of +-45 degrees;
- ``box``: as shipped with the box reconstruction (one sample per lenslet);
- ``exposure / 5``: as shipped, the LF camera's exposure 0.05 instead of 0.25 (no code saturates).

Run: python benchmarks/reconstruction/where_the_error_is.py   (about 2 minutes, the first run longer: it renders
the ground truth into the cache). The table is in docs/architecture.md ("Where the cross error comes from").
"""

from __future__ import annotations

from dataclasses import replace

from lftransfer.runs.bench.step import transfer_settings
from lftransfer.runs.pipeline import RunOptions, knowledge, open_rig
from lftransfer.scenes import quick_scene
from lftransfer.scenes import builtin_scene, load_scene, with_overrides
from lftransfer.sim.metrics import evaluate
from lftransfer.transfer.bounce import run_transfer
from study_scenes import GT_SPP, by_side_cells


def variants(scene):
    r = scene.rig
    yield "as shipped", scene, "linear"
    yield "half pitch", with_overrides(scene, rig={
        "rows": 2 * r.rows, "cols": 2 * r.cols, "pitch_mm": r.pitch_mm / 2, "focal_mm": r.focal_mm / 2,
        "lf_camera": [2 * v for v in r.lf_camera], "projector": [2 * v for v in r.projector]}), "linear"
    yield "wide window", with_overrides(scene, rig={"focal_mm": r.focal_mm / 2}), "linear"
    yield "box", scene, "box"
    yield "exposure / 5", with_overrides(scene, rig={"exposure": r.exposure / 5}), "linear"


def main() -> None:
    base = quick_scene(load_scene(builtin_scene("fig4")))
    print("| rig | cross error | real side: error, energy ratio, error after best scale | synthetic side: the same "
          "| ground truth's noise (real / synthetic) |")
    print("|---|---|---|---|---|")
    for name, scene, reconstruction in variants(base):
        opened = open_rig(scene, RunOptions(truth_seed=1))
        known = knowledge(opened, scene, "oracle")
        settings = replace(transfer_settings(scene), bounces=2, reconstruction=reconstruction)
        opened.start_frame(0)
        result = run_transfer(opened.rig, known.model, known.scene, settings)
        m = evaluate(result, opened.oracle.ground_truth(spp=GT_SPP))
        print(f"| {name} | {m.cross_transfer_rel_error:.3f} {by_side_cells(m)}", flush=True)


if __name__ == "__main__":
    main()

"""A study of the window: does reading the captured light field at the lenslets' window edge for light steeper
than the window (``[render] window = "edge"``, :mod:`lftransfer.render.lights`) bring the synthetic objects the
light that the lens array cannot record, on scenes other than Fig. 4 too?

Each scene runs twice, with ``window = "cut"`` (nothing arrives from beyond the window, the light field as the
hardware records it) and ``"edge"``, and prints ``cross_by_side`` as ``where_the_error_is.py`` does. Scenes:
Fig. 4 and the five scenes of this folder (true rig model, truth seed 2, the linear reconstruction, the depth
prefilter, 2 bounces); at quarter resolution (ground truth 8192 samples per pixel) or, with ``--full``, at the
paper's (ground truth 512).

Run: python benchmarks/reconstruction/window.py [--full]   (about a minute at quarter resolution once the ground
truths are cached, 4 minutes with --full). The table is in docs/architecture.md ("Light from beyond the window").
"""

from __future__ import annotations

import sys
from dataclasses import replace

from lftransfer.runs.bench.step import transfer_settings
from lftransfer.runs.pipeline import RunOptions, knowledge, open_rig
from lftransfer.sim.metrics import evaluate
from lftransfer.transfer.bounce import run_transfer
from study_scenes import GT_SPP, by_side_cells, study_scenes

WINDOWS = ("cut", "edge")


def main(full: bool) -> None:
    print("| scene | window | cross error | real side: error, energy ratio, error after best scale "
          "| synthetic side: the same | ground truth's noise (real / synthetic) |")
    print("|---|---|---|---|---|---|")
    for name, scene in study_scenes(full):
        for window in WINDOWS:
            opened = open_rig(scene, RunOptions(truth_seed=2))
            known = knowledge(opened, scene, "oracle")
            settings = replace(transfer_settings(scene), bounces=2, reconstruction="linear", window=window)
            opened.start_frame(0)
            result = run_transfer(opened.rig, known.model, known.scene, settings)
            m = evaluate(result, opened.oracle.ground_truth(spp=512 if full else GT_SPP))
            print(f"| {name} | {window} | {m.cross_transfer_rel_error:.3f} {by_side_cells(m)}", flush=True)


if __name__ == "__main__":
    main("--full" in sys.argv[1:])

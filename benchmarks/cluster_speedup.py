"""Speed-up of a converged sequence on a local Ray cluster against one process, and whether the frames agree.

Renders the same converged sequence (frames and their path-traced ground truths, the code ``lft render --mode
converged --verify-every 1`` runs) twice: in this process, then with ``--cluster local`` (one worker per CPU core
unless ``--workers`` says otherwise). Prints one JSON object: the wall time of each (the sequence alone, set-up
included: the cluster's start and its workers' first kernels count against it), the speed-up, the machine's
load average during the runs, and whether every frame's EXR and metrics are identical.

Usage: ``python benchmarks/cluster_speedup.py [--scene fig5] [--frames 12] [--gt-spp 512] [--workers N]
[--out out/cluster_speedup]`` (quarter resolution, oracle rig model, no ground-truth cache).
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

import numpy as np

from lftransfer.runs.cluster import ClusterSpec
from lftransfer.runs.pipeline import RunOptions
from lftransfer.scenes import quick_scene
from lftransfer.settings import Overrides
from lftransfer.runs.sequence import SequenceOptions, render_sequence
from lftransfer.imageio_utils import read_exr
from lftransfer.scenes import builtin_scene, load_scene


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--scene", default="fig5")
    parser.add_argument("--frames", type=int, default=12)
    parser.add_argument("--gt-spp", type=int, default=512)
    parser.add_argument("--workers", type=int, default=None)
    parser.add_argument("--out", type=Path, default=Path("out/cluster_speedup"))
    args = parser.parse_args()
    scene = quick_scene(load_scene(builtin_scene(args.scene)))
    options = RunOptions(rig_model="oracle", truth_seed=0, use_cache=False, settings=Overrides(gt_spp=args.gt_spp))
    runs, load = {}, []
    for name, cluster in (("one_process", None), ("local_cluster", ClusterSpec("local", workers=args.workers))):
        seq = SequenceOptions(mode="converged", frames=args.frames, verify_every=1, cluster=cluster)
        t0 = time.perf_counter()
        runs[name] = render_sequence(scene, args.out / name, options, seq)
        runs[name]["wall_s"] = time.perf_counter() - t0
        load.append(os.getloadavg()[0])
    frames = range(args.frames)
    same_exr = all(np.array_equal(read_exr(args.out / "one_process" / "frames" / f"{i:04d}.exr"),
                                  read_exr(args.out / "local_cluster" / "frames" / f"{i:04d}.exr")) for i in frames)
    same_metrics = [f["metrics"] for f in runs["one_process"]["frames"]] == \
        [f["metrics"] for f in runs["local_cluster"]["frames"]]
    one, many = runs["one_process"]["wall_s"], runs["local_cluster"]["wall_s"]
    print(json.dumps({"scene": args.scene, "frames": args.frames, "gt_spp": args.gt_spp,
                      "resolution": list(scene.view.resolution), "cpu_count": os.cpu_count(),
                      "workers": runs["local_cluster"]["cluster"]["workers"],
                      "one_process_s": round(one, 1), "local_cluster_s": round(many, 1),
                      "speedup": round(one / many, 2), "load_average_after_each": [round(x, 1) for x in load],
                      "frames_identical": same_exr, "metrics_identical": same_metrics}, indent=1))


if __name__ == "__main__":
    main()

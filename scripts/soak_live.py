"""A soak of ``lft live``: the decoupled loop and its page for many minutes, a slider moved every second.

Runs :func:`measure_live_fps.measure` (the page's websocket, as a browser) for ``--minutes`` with an edit every
second, and reports what a long session must keep: resident memory flat (its growth from the end of the first
minute to the end, against 5 %), no frame stalled (the longest gap between frames, and the longest edit-to-pixel
latency, against 1 s), the frames delivered per second throughout.

Usage:
    python scripts/soak_live.py [SCENE.toml] [--quick] [--minutes 10] [--rig-model oracle] [--json OUT]
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from measure_live_fps import measure, report  # noqa: E402

from lftransfer.choices import DEFAULT_RIG_MODEL, RIG_MODELS  # noqa: E402

GROWTH_LIMIT = 0.05      # resident memory may grow this much after the first minute
STALL_S = 1.0            # no gap between frames, nor edit-to-pixel latency, above this


def main() -> None:
    from lftransfer.app.cli.common import load

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("scene", nargs="?", type=Path, default=None)
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--minutes", type=float, default=10.0)
    parser.add_argument("--calibration", type=Path, default=None)
    parser.add_argument("--rig-model", default=DEFAULT_RIG_MODEL, choices=RIG_MODELS)
    parser.add_argument("--port", type=int, default=8788)
    parser.add_argument("--json", type=Path, default=None)
    args = parser.parse_args()
    scene = load(args.scene, args.quick)
    run = measure(scene, "decoupled", args, seconds=60.0 * args.minutes, edit_every=1.0)
    rss = run["rss_mb"]
    after_minute = [mb for t, mb in rss if t >= 60.0]
    growth = (after_minute[-1] - after_minute[0]) / after_minute[0] if len(after_minute) > 1 else None
    result = {"scene": str(scene.source), "quick": args.quick, "minutes": args.minutes, "loop": "decoupled",
              "rig_model": args.rig_model, "view": list(scene.view.resolution), "lf_camera": list(scene.rig.lf_camera),
              "machine": {"cpus": os.cpu_count(), "load_average": [round(x, 2) for x in os.getloadavg()]},
              "rss_growth_after_first_minute": None if growth is None else round(growth, 4),
              "rss_growth_limit": GROWTH_LIMIT, "stall_limit_s": STALL_S,
              "memory_flat": growth is not None and growth < GROWTH_LIMIT,
              "no_stall": (run["longest_gap_s"] or 0) <= STALL_S and (run["edit_to_pixel_max_ms"] or 0) <= 1000 * STALL_S
              and run["edits_unseen"] <= 1,
              **run}
    report(result, args.json)


if __name__ == "__main__":
    main()

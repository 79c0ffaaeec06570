"""Profile the live loop's pipeline (everything but the rig's capture) at the paper's resolution.

Runs ``LiveTransfer.step`` on the simulated rig for two warm-up frames (the depth measured, the kernels compiled,
the culling tiles built), then repeats the pipeline's stages on the last frame's capture, without the simulator:
encode the synthetic light field, decode the LF camera image, make the captured light field a light, render the
light field and the view, prefilter, composite. Prints the median time per stage and, with ``--py-spy FILE``,
is meant to run under py-spy (``py-spy record --format raw -o FILE -- python scripts/profile_pipeline.py ...``);
``--top FILE`` summarises such a raw profile: the functions with the most samples of their own (self) and in
total (inclusive), as docs/performance.md lists them.

Usage:
    python scripts/profile_pipeline.py [--quick] [--calibration FILE] [--repeats 20] [--json OUT]
    py-spy record --native --format raw -o prof.txt -- python scripts/profile_pipeline.py --calibration FILE
    python scripts/profile_pipeline.py --top prof.txt
"""

from __future__ import annotations

import argparse
import json
import statistics
import time
from collections import Counter
from pathlib import Path


def pipeline_stages(live, frame, repeats: int) -> dict[str, list[float]]:
    """Seconds per stage over ``repeats`` runs of the pipeline on ``frame``'s capture (the rig is not used)."""
    from lftransfer.composite import composite
    from lftransfer.transfer.timer import StageTimer

    side, s = live.side, live.settings
    runs: dict[str, list[float]] = {}
    for _ in range(repeats):
        timer = StageTimer()
        with timer("encode"):
            side.encoder(frame.synthetic_lf)
        with timer("decode"):
            captured = side.decoder(frame.captured_raw)
        with timer("incident_light"):
            lights = [*side.direct_lights, side.incident_light(captured, s.seed)]
        _, view = side.render(lights, s.seed, timer)
        with timer("composite"):
            composite(view.rgb, view.alpha, frame.real_view)
        for k, v in timer.totals.items():
            runs.setdefault(k, []).append(v)
        runs.setdefault("total", []).append(sum(timer.totals.values()))
    return runs


def top(raw: Path, n: int = 15) -> dict:
    """The functions with the most samples in a py-spy raw (collapsed stacks) profile: self and inclusive."""
    own: Counter = Counter()
    inclusive: Counter = Counter()
    total = 0
    for line in raw.read_text().splitlines():
        stack, _, count = line.rpartition(" ")
        if not stack:
            continue
        c = int(count)
        total += c
        frames = [f.split(" (")[0].strip() + (" (" + f.split(" (")[1].split(":")[0] + ")" if " (" in f else "")
                  for f in stack.split(";")]
        own[frames[-1]] += c
        for f in set(frames):
            inclusive[f] += c
    pct = lambda c: round(100.0 * c / total, 1)           # noqa: E731
    return {"samples": total, "self": [(f, pct(c)) for f, c in own.most_common(n)],
            "inclusive": [(f, pct(c)) for f, c in inclusive.most_common(n)]}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--calibration", type=Path, default=None, help="calibration file (default: oracle model)")
    parser.add_argument("--repeats", type=int, default=20)
    parser.add_argument("--json", type=Path, default=None)
    parser.add_argument("--top", type=Path, default=None, help="summarise this py-spy raw profile and stop")
    args = parser.parse_args()
    if args.top is not None:
        print(json.dumps(top(args.top), indent=1))
        return

    from lftransfer.app.bench.step import transfer_settings
    from lftransfer.app.cli.common import load
    from lftransfer.app.pipeline import RunOptions
    from lftransfer.app.rigs import open_rig
    from lftransfer.calibration.rig import load_calibration
    from lftransfer.transfer.live import LiveTransfer

    scene = load(None, args.quick)
    opened = open_rig(scene, RunOptions(truth_seed=0))
    model = load_calibration(args.calibration, scene.synthetic_part()).model if args.calibration else \
        opened.oracle.model
    settings = transfer_settings(scene)
    live = LiveTransfer(opened.rig, model, scene.synthetic_part(), settings)
    t0 = time.perf_counter()
    frame = live.step(0.0)
    frame = live.step(0.0)
    warm = time.perf_counter() - t0
    runs = pipeline_stages(live, frame, args.repeats)
    result = {"resolution": {"lf_camera": list(scene.rig.lf_camera), "projector": list(scene.rig.projector),
                             "view": list(scene.view.resolution)},
              "warmup_s": round(warm, 1), "repeats": args.repeats,
              "stages_ms": {k: round(1000 * statistics.median(v), 2) for k, v in runs.items()}}
    print(json.dumps(result, indent=1))
    if args.json:
        args.json.write_text(json.dumps(result, indent=1))


if __name__ == "__main__":
    main()

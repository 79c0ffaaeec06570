"""Profile the live loop's pipeline (everything but the rig's capture) at the paper's resolution.

Runs ``LiveTransfer.step`` on the simulated rig for two warm-up frames (the depth measured, the kernels compiled,
the culling tiles built), then repeats the pipeline's stages on the last frame's capture, without the simulator:
encode the synthetic light field, decode the LF camera image, make the captured light field a light, render the
light field and the view, prefilter, composite. It writes the median time per stage (a run of its own, not
sampled) and, with ``--py-spy``, runs itself again under py-spy (``py-spy record --native --format raw``) and
adds the profile's top entries over the repeated stages only (the warm-up and the simulator left out): the
functions with the most samples of their own (self) and in total (inclusive), as docs/performance.md lists them.

``--src DIR`` profiles the lftransfer found in another checkout (``git worktree add DIR COMMIT``): the profile
before a change, by the same script.

Usage:
    python scripts/profile_pipeline.py [--quick] [--calibration FILE] [--repeats 20] [--py-spy] [--src DIR]
        [--json OUT]
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


def _frame(text: str) -> str:
    """``function (file)`` of a py-spy frame ``function (file:line)`` (the line left out, so that a function's
    samples add up)."""
    name, _, where = text.strip().partition(" (")
    return f"{name} ({where.rstrip(')').split(':')[0]})" if where else name


def top(raw: Path, n: int = 15, within: str = "pipeline_stages") -> dict:
    """The functions with the most samples in a py-spy raw (collapsed stacks) profile, over the stacks that pass
    through ``within``: self and inclusive, per cent of those samples."""
    own: Counter = Counter()
    inclusive: Counter = Counter()
    total = 0
    for line in raw.read_text().splitlines():
        stack, _, count = line.rpartition(" ")
        if not stack or within not in stack:
            continue
        c = int(count)
        total += c
        frames = [_frame(f) for f in stack.split(";")]
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
    parser.add_argument("--py-spy", action="store_true", help="also profile a second run under py-spy")
    parser.add_argument("--src", type=Path, default=None, help="a checkout whose src/lftransfer to profile")
    args = parser.parse_args()
    source = None
    if args.src is not None:
        import subprocess
        import sys

        sys.path.insert(0, str((args.src / "src").resolve()))
        source = {"checkout": str(args.src), "commit": subprocess.run(
            ["git", "-C", str(args.src), "rev-parse", "HEAD"], capture_output=True, text=True).stdout.strip()}

    from lftransfer.runs.bench.step import transfer_settings
    from lftransfer.app.cli.common import load
    from lftransfer.runs.pipeline import RunOptions
    from lftransfer.runs.rigs import open_rig
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
              "warmup_s": round(warm, 1), "repeats": args.repeats, "source": source,
              "stages_ms": {k: round(1000 * statistics.median(v), 2) for k, v in runs.items()}}
    live.close()
    opened.rig.close()
    if args.py_spy:
        result["py_spy"] = _py_spy(args)
    print(json.dumps(result, indent=1))
    if args.json:
        from lftransfer.imageio_utils import write_json

        write_json(args.json, result)


def _py_spy(args) -> dict:
    """This script's stages again under py-spy (100 samples per second, native frames): the top entries."""
    import shutil
    import subprocess
    import sys
    import tempfile

    spy = shutil.which("py-spy") or str(Path(sys.executable).with_name("py-spy"))
    with tempfile.TemporaryDirectory() as tmp:
        raw = Path(tmp) / "profile.txt"
        cmd = [spy, "record", "--native", "--format", "raw", "--rate", "100", "-o", str(raw), "--",
               sys.executable, __file__, "--repeats", str(args.repeats)]
        cmd += ["--quick"] if args.quick else []
        cmd += ["--calibration", str(args.calibration)] if args.calibration else []
        cmd += ["--src", str(args.src)] if args.src else []
        subprocess.run(cmd, check=True, capture_output=True)
        return {"command": " ".join(["py-spy", *cmd[1:7], "--", "python", "scripts/profile_pipeline.py",
                                     *cmd[cmd.index("--repeats"):]]),
                **top(raw)}


if __name__ == "__main__":
    main()

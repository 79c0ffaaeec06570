"""Run the commands behind docs/results.md and store their JSON, with provenance, in docs/runs/ (``make runs``).

    python scripts/store_runs.py                 # every run of lftransfer.reports.results.RUNS (hours on 2 cores)
    python scripts/store_runs.py --quick         # the quarter-resolution runs only (minutes)
    python scripts/store_runs.py demo bench      # these runs (and the runs they need: bench reads demo's calibration)
    python scripts/store_runs.py --list          # the runs, their commands, and which are stored
    python scripts/store_runs.py --adopt twin_compare=out/twin_compare/twin_compare.json   # see --adopt

Each run's commands are the ones a user types (``lft demo``, ``lft run``, ``lft bench --json``, ``lft render``,
``lft calibrate seeds``, ``python benchmarks/twin/compare.py``), run from the repository root with this Python's
``lft`` into ``out/runs/``; their output goes to ``out/runs/logs/NAME.log``. When they succeed, the JSON they wrote
is copied into ``docs/runs/NAME.json`` with a provenance block: the commands, the git commit (and whether the working
tree had uncommitted changes), the date, the machine (CPUs, platform, load average at the start) and the wall time.
A run that fails stores nothing and keeps the stored file it had. Then ``make results`` rewrites docs/results.md.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import time
from datetime import datetime, timezone
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

from lftransfer.reports.results import RUN_BY_NAME, RUNS, Run, load_run  # noqa: E402

STORE = ROOT / "docs" / "runs"
LOGS = ROOT / "out" / "runs" / "logs"


def git(*args: str) -> str:
    done = subprocess.run(["git", "-C", str(ROOT), *args], capture_output=True, text=True)
    return done.stdout.strip() if done.returncode == 0 else ""


def machine() -> dict:
    info: dict = {"cpus": os.cpu_count(), "platform": platform.platform(), "python": platform.python_version()}
    try:
        info["load_average"] = [round(x, 2) for x in os.getloadavg()]
    except OSError:
        pass
    if shutil.which("nvidia-smi"):
        gpu = subprocess.run(["nvidia-smi", "--query-gpu=name", "--format=csv,noheader"], capture_output=True,
                             text=True)
        if gpu.returncode == 0 and gpu.stdout.strip():
            info["gpu"] = gpu.stdout.strip().replace("\n", ", ")
    return info


def executable(argv: tuple[str, ...]) -> list[str]:
    """The command as typed, with ``lft`` and ``python`` resolved to this environment's."""
    head = argv[0]
    if head == "lft":
        lft = Path(sys.executable).with_name("lft")
        return [str(lft) if lft.exists() else "lft", *argv[1:]]
    if head == "python":
        return [sys.executable, *argv[1:]]
    return list(argv)


def collect(run: Run) -> dict:
    """What the run wrote: the JSON of its files (one file: the data itself)."""
    data: dict = {}
    for key, rel in run.files:
        path = ROOT / rel
        if not path.is_file():
            if key == "effect":          # a sequence without an [effect]
                data[key] = None
                continue
            raise SystemExit(f"error: {run.name}: the run did not write {rel}")
        value = json.loads(path.read_text(encoding="utf-8"))
        if key == "":
            data = value
        else:
            data[key] = value
    if run.kind == "sequence":           # the frames' own timings per stage are bulky; keep the rest
        for frame in data["report"].get("frames", []):
            frame.pop("timings_s", None)
    return data


def store(run: Run, data: dict, provenance: dict) -> Path:
    STORE.mkdir(parents=True, exist_ok=True)
    path = STORE / f"{run.name}.json"
    tmp = path.with_suffix(".json.tmp")
    tmp.write_text(json.dumps({"run": run.name, "kind": run.kind, "provenance": provenance, "data": data},
                              indent=1, allow_nan=True) + "\n", encoding="utf-8")
    tmp.replace(path)
    load_run(path)                       # what the generator reads must load
    return path


def execute(run: Run) -> Path:
    LOGS.mkdir(parents=True, exist_ok=True)
    log = LOGS / f"{run.name}.log"
    started = datetime.now(timezone.utc)
    provenance = {"commands": [" ".join(c) for c in run.commands], "commit": git("rev-parse", "HEAD"),
                  "dirty": bool(git("status", "--porcelain", "--untracked-files=no", "--", ".", ":!docs/runs",
                                     ":!docs/results.md")),   # what this script writes itself does not count
                  "date": started.strftime("%Y-%m-%d %H:%M UTC"), "machine": machine()}
    t0 = time.perf_counter()
    # a stored run calibrates as a first run does (its timings include the calibration): a calibration cache of
    # its own, empty; the same report either way (a cached calibration restores the rig's noise)
    calibrations = tempfile.TemporaryDirectory(prefix="lft-store-calibrations-")
    env = {**os.environ, "COLUMNS": "120", "LFT_CALIBRATION_CACHE_DIR": calibrations.name}
    with log.open("w") as f, calibrations:
        for argv in run.commands:
            print(f"[{run.name}] + {' '.join(argv)}", flush=True)
            f.write(f"+ {' '.join(argv)}\n")
            f.flush()
            done = subprocess.run(executable(argv), cwd=ROOT, stdout=f, stderr=subprocess.STDOUT, env=env)
            if done.returncode != 0:
                raise SystemExit(f"error: {run.name}: `{' '.join(argv)}` exited with {done.returncode}; "
                                 f"see {log.relative_to(ROOT)} (nothing stored)")
    provenance["wall_s"] = round(time.perf_counter() - t0, 1)
    path = store(run, collect(run), provenance)
    print(f"[{run.name}] stored {path.relative_to(ROOT)} ({provenance['wall_s']} s)", flush=True)
    return path


def adopt(spec: str) -> Path:
    """``NAME=FILE``: store JSON a run already wrote, without running it again. Only for a run whose JSON carries
    its own provenance (benchmarks/twin/compare.py writes its commit, date and machine; scripts/paired_bench.py its
    two commits, date, machine and wall time)."""
    name, _, file = spec.partition("=")
    run = RUN_BY_NAME.get(name)
    if run is None or not file:
        raise SystemExit(f"error: --adopt {spec}: expected NAME=FILE with NAME one of {', '.join(RUN_BY_NAME)}")
    if run.kind not in ("twin_compare", "paired"):
        raise SystemExit(f"error: --adopt {name}: its JSON has no provenance of its own; run it instead")
    path = Path(file)
    data = json.loads(path.read_text(encoding="utf-8"))
    if run.kind == "paired":
        return _adopt_paired(run, path, data)
    for key in ("commit", "date", "machine"):
        if key not in data:
            raise SystemExit(f"error: {path}: missing field '{key}' (needed for the provenance)")
    out_dir = path.parent.as_posix()
    command = f"python benchmarks/twin/compare.py --out {out_dir}"
    if not data.get("quick", True):
        command += " --full"
    if data.get("gt_spp") not in (None, 4096):
        command += f" --gt-spp {data['gt_spp']}"
    if data.get("live_frames") not in (None, 10):
        command += f" --frames {data['live_frames']}"
    provenance = {"commands": [command], "commit": data["commit"], "date": data["date"], "machine": data["machine"],
                  "wall_s": None,
                  "note": f"Stored from {path.as_posix()} as written by that command (not run again by "
                          f"scripts/store_runs.py), so its wall time is not recorded."}
    stored = store(run, data, provenance)
    print(f"[{name}] stored {stored.relative_to(ROOT)} from {path}")
    return stored


def _adopt_paired(run: Run, path: Path, data: dict) -> Path:
    for key in ("a", "b", "date", "machine", "rounds", "bench_args", "wall_s"):
        if key not in data:
            raise SystemExit(f"error: {path}: missing field '{key}' (needed for the provenance)")
    command = (f"python scripts/paired_bench.py --against {data['a']['ref']} --with {data['b']['ref']} "
               f"--rounds {data['rounds']} --json {path.as_posix()} -- {' '.join(data['bench_args'])}")
    machine = {k: v for k, v in data["machine"].items() if k != "load_average_end"}
    machine["load_average"] = machine.pop("load_average_start", None)
    provenance = {"commands": [command], "commit": data["b"]["commit"], "date": data["date"], "machine": machine,
                  "wall_s": data["wall_s"],
                  "note": f"Stored from {path.as_posix()} as written by that command (not run again by "
                          f"scripts/store_runs.py); the commit is side B's, the one measured against side A's."}
    stored = store(run, data, provenance)
    print(f"[{run.name}] stored {stored.relative_to(ROOT)} from {path}")
    return stored


def order(names: list[str]) -> list[Run]:
    """The runs asked for, in the order of RUNS, each after the runs it needs when their files are missing (the
    calibration files its commands read: bench reads out/runs/demo/calibration.json)."""
    chosen: list[Run] = []

    def add(name: str) -> None:
        run = RUN_BY_NAME[name]
        if run in chosen:
            return
        if any(not (ROOT / p).is_file() for p in inputs(run)):
            for need in run.needs:
                add(need)
        chosen.append(run)

    for name in sorted(set(names), key=[r.name for r in RUNS].index):
        add(name)
    return chosen


def inputs(run: Run) -> list[str]:
    """The files of other runs that ``run``'s commands read (``--calibration FILE`` that no earlier command of the
    run writes)."""
    written = set()
    out = []
    for argv in run.commands:
        for i, arg in enumerate(argv[:-1]):
            if arg == "--calibration" and argv[i + 1] not in written:
                out.append(argv[i + 1])
            if arg == "--out":
                written.add(argv[i + 1])
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("names", nargs="*", help=f"runs to store (default: all): {', '.join(RUN_BY_NAME)}")
    ap.add_argument("--quick", action="store_true", help="only the quarter-resolution runs")
    ap.add_argument("--list", action="store_true", help="list the runs and which are stored, and stop")
    ap.add_argument("--adopt", action="append", default=[], metavar="NAME=FILE",
                    help="store JSON a run already wrote (twin_compare and paired runs only: their JSON holds "
                         "their provenance)")
    args = ap.parse_args()
    unknown = [n for n in args.names if n not in RUN_BY_NAME]
    if unknown:
        ap.error(f"unknown run(s) {', '.join(unknown)}; known: {', '.join(RUN_BY_NAME)}")
    if args.list:
        for run in RUNS:
            stored = "stored" if (STORE / f"{run.name}.json").is_file() else "not stored"
            print(f"{run.name:18s} {'quick' if run.quick else 'full ':5s} {stored:10s} {run.command_line}")
        return
    for spec in args.adopt:
        adopt(spec)
    if args.adopt and not args.names and not args.quick:
        return
    names = args.names or [r.name for r in RUNS if r.quick or not args.quick]
    for run in order(names):
        execute(run)


if __name__ == "__main__":
    main()

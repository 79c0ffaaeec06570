"""A paired speed check across commits: ``lft bench`` of two checkouts, alternated on this machine.

    python scripts/paired_bench.py --against 84066a4                 # that commit against this working tree
    python scripts/paired_bench.py --against 8184fa7 --with HEAD --rounds 3 --json out/paired.json
    python scripts/paired_bench.py --against main -- --quick --iterations 5    # bench options after --

A speed figure moves with the machine's load by more than most changes move it, so a claim across commits ("this
is faster", "that is only load") is made from one run that times both, not from two runs on two days
(docs/performance.md, "Comparing commits"). Each side is a clean clone of its commit in ``out/paired/`` (or, for
``--with worktree``, this checkout as it is, uncommitted changes included); both run with this environment's
Python and packages (``PYTHONPATH`` points at the side's ``src``; the script checks that each imports its own
code). The benches alternate A B, B A, A B, ... so that a drift of the machine's load falls on both sides alike,
and the table gives, per stage, the median over the rounds of each bench's own median, the spread of those, and
the ratio B / A (below 1: B is faster).

Default bench options: ``--rig-model oracle --no-peer --no-accuracy --iterations 10`` (the paper's resolution,
no calibration: only the step's speed is compared).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shlex
import statistics
import subprocess
import sys
import tempfile
import time
from datetime import datetime, timezone
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CLONES = ROOT / "out" / "paired"
DEFAULT_BENCH = ("--rig-model", "oracle", "--no-peer", "--no-accuracy", "--iterations", "10")
STAGES = ("pose", "encode", "decode", "incident_light", "render_lightfield", "prefilter", "surface_target",
          "render_view", "composite")
TOTALS = ("pipeline_iteration_ms", "floor_ms", "capture_ms")


def git(*args: str, cwd: Path = ROOT) -> str:
    done = subprocess.run(["git", "-C", str(cwd), *args], capture_output=True, text=True)
    if done.returncode != 0:
        raise SystemExit(f"error: git {' '.join(args)}: {done.stderr.strip()}")
    return done.stdout.strip()


def checkout(ref: str) -> tuple[Path, str, str]:
    """The source folder of ``ref`` (a clean clone at its commit; ``worktree``: this checkout), its commit and a
    label."""
    if ref == "worktree":
        dirty = bool(git("status", "--porcelain", "--untracked-files=no"))
        commit = git("rev-parse", "HEAD")
        return ROOT, commit, f"worktree ({commit[:8]}{', uncommitted changes' if dirty else ''})"
    commit = git("rev-parse", "--verify", f"{ref}^{{commit}}")
    where = CLONES / f"src_{commit[:12]}"
    if not (where / ".git").is_dir():
        CLONES.mkdir(parents=True, exist_ok=True)
        tmp = Path(tempfile.mkdtemp(prefix="clone_", dir=CLONES))
        subprocess.run(["git", "clone", "--quiet", "--no-checkout", str(ROOT), str(tmp)], check=True)
        subprocess.run(["git", "-C", str(tmp), "checkout", "--quiet", commit], check=True)
        tmp.replace(where)
    elif git("rev-parse", "HEAD", cwd=where) != commit or git("status", "--porcelain", cwd=where):
        raise SystemExit(f"error: {where} is not a clean clone of {commit[:12]}; remove it and run again")
    return where, commit, f"{ref} ({commit[:8]})"


def side_env(src: Path) -> dict:
    env = {**os.environ, "PYTHONPATH": str(src / "src"), "COLUMNS": "120"}
    done = subprocess.run([sys.executable, "-c", "import lftransfer; print(lftransfer.__file__)"], env=env,
                          capture_output=True, text=True, cwd=ROOT)
    imported = Path(done.stdout.strip()).resolve() if done.returncode == 0 else None
    if imported is None or (src / "src").resolve() not in imported.parents:
        raise SystemExit(f"error: with PYTHONPATH={src / 'src'} Python imports lftransfer from {imported} "
                         f"instead of that checkout: {done.stderr.strip()[-300:]}")
    return env


def lft_entry(src: Path) -> str:
    """The ``lft`` command's entry point in that checkout (``module:attribute`` of its pyproject.toml)."""
    import tomllib

    scripts = tomllib.loads((src / "pyproject.toml").read_text(encoding="utf-8"))["project"].get("scripts", {})
    if "lft" not in scripts:
        raise SystemExit(f"error: {src / 'pyproject.toml'}: no [project.scripts] lft entry point")
    return scripts["lft"]


def bench_once(src: Path, env: dict, bench_args: list[str], log: Path) -> dict:
    """One ``lft bench`` of the checkout at ``src`` (its own entry point, with this Python); its JSON."""
    module, _, attr = lft_entry(src).partition(":")
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "bench.json"
        argv = [sys.executable, "-c", f"import sys; from {module} import {attr} as lft; sys.argv[0] = 'lft'; lft()",
                "bench", *bench_args, "--json", str(out)]
        with log.open("a") as f:
            f.write(f"+ PYTHONPATH={env['PYTHONPATH']} {shlex.join(argv)}\n")
            f.flush()
            done = subprocess.run(argv, cwd=ROOT, env=env, stdout=f, stderr=subprocess.STDOUT)
        if done.returncode != 0:
            raise SystemExit(f"error: the bench of {src} exited with {done.returncode}; see {log}")
        return json.loads(out.read_text(encoding="utf-8"))


def figures(bench: dict) -> dict[str, float]:
    """The bench's per-stage medians and totals, ms."""
    out = {k: float(bench[k]) for k in TOTALS if bench.get(k) is not None}
    for name, spread in bench.get("stages_ms", {}).items():
        out[name] = float(spread["median"])
    return out


def summarise(runs_a: list[dict], runs_b: list[dict]) -> list[dict]:
    """Per figure: median over the rounds of each side (with min and max), and the ratio B / A of the medians."""
    a = [figures(r) for r in runs_a]
    b = [figures(r) for r in runs_b]
    names = [n for n in (*TOTALS[:1], *STAGES, *TOTALS[1:]) if any(n in x for x in a + b)]
    names += sorted({n for x in a + b for n in x} - set(names))
    rows = []
    for name in names:
        va = [x[name] for x in a if name in x]
        vb = [x[name] for x in b if name in x]
        ma = statistics.median(va) if va else None
        mb = statistics.median(vb) if vb else None
        rows.append({"figure": name, "a_ms": ma, "a_range": [min(va), max(va)] if va else None,
                     "b_ms": mb, "b_range": [min(vb), max(vb)] if vb else None,
                     "ratio": (mb / ma) if ma and mb is not None else None})
    return rows


def print_table(rows: list[dict], label_a: str, label_b: str) -> None:
    def ms(v, r):
        return "-" if v is None else f"{v:8.2f} [{r[0]:.1f}, {r[1]:.1f}]"

    print(f"A = {label_a}\nB = {label_b}\n")
    print("ms: the median over the rounds of each bench's own median [lowest, highest]\n")
    print(f"{'figure':<28} {'A':>24} {'B':>24} {'B / A':>7}")
    for row in rows:
        ratio = "-" if row["ratio"] is None else f"{row['ratio']:.3f}"
        print(f"{row['figure']:<28} {ms(row['a_ms'], row['a_range']):>24} {ms(row['b_ms'], row['b_range']):>24} "
              f"{ratio:>7}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0],
                                 epilog="Options after -- go to lft bench (default: " + " ".join(DEFAULT_BENCH) + ")")
    ap.add_argument("--against", required=True, metavar="REF", help="side A: a commit, tag or branch")
    ap.add_argument("--with", dest="with_", default="worktree", metavar="REF",
                    help="side B: a commit, or 'worktree' (default): this checkout with its uncommitted changes")
    ap.add_argument("--rounds", type=int, default=3, help="benches per side, alternated (default 3)")
    ap.add_argument("--json", type=Path, help="write the pairing (every bench's figures and the table) here")
    ap.add_argument("bench_args", nargs="*", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.rounds < 1:
        raise SystemExit(f"error: --rounds: expected an integer >= 1, got {args.rounds}")
    bench_args = list(args.bench_args) or list(DEFAULT_BENCH)
    if "--json" in bench_args:
        raise SystemExit("error: give --json to this script, not to lft bench (each bench writes its own)")

    src_a, commit_a, label_a = checkout(args.against)
    src_b, commit_b, label_b = checkout(args.with_)
    env_a, env_b = side_env(src_a), side_env(src_b)
    CLONES.mkdir(parents=True, exist_ok=True)
    log = CLONES / "paired.log"
    log.write_text("", encoding="utf-8")
    load = os.getloadavg()
    started = datetime.now(timezone.utc)
    t0 = time.perf_counter()
    runs_a: list[dict] = []
    runs_b: list[dict] = []
    for r in range(args.rounds):
        order = (("A", src_a, env_a, runs_a), ("B", src_b, env_b, runs_b))
        for name, src, env, runs in (order if r % 2 == 0 else order[::-1]):
            print(f"round {r + 1}/{args.rounds}: bench {name}", flush=True)
            runs.append(bench_once(src, env, bench_args, log))
    rows = summarise(runs_a, runs_b)
    print()
    print_table(rows, label_a, label_b)
    if args.json:
        data = {"a": {"ref": args.against, "commit": commit_a, "label": label_a},
                "b": {"ref": args.with_, "commit": commit_b, "label": label_b},
                "bench_args": bench_args, "rounds": args.rounds, "order": "A B, B A, ... alternated per round",
                "date": started.strftime("%Y-%m-%d %H:%M UTC"), "wall_s": round(time.perf_counter() - t0, 1),
                "machine": {"cpus": os.cpu_count(), "platform": platform.platform(),
                            "load_average_start": [round(x, 2) for x in load],
                            "load_average_end": [round(x, 2) for x in os.getloadavg()]},
                "rows": rows,
                "runs": {"a": [figures(r) for r in runs_a], "b": [figures(r) for r in runs_b]},
                "settings": {"a": runs_a[0].get("settings"), "b": runs_b[0].get("settings")}}
        args.json.parent.mkdir(parents=True, exist_ok=True)
        tmp = args.json.with_suffix(args.json.suffix + ".tmp")
        tmp.write_text(json.dumps(data, indent=1) + "\n", encoding="utf-8")
        tmp.replace(args.json)
        print(f"\nwrote {args.json}")


if __name__ == "__main__":
    main()

"""docs/results.md from the stored runs' JSON (docs/runs/*.json): ``make results``.

    python -m lftransfer.reports.results docs/runs docs/results.md

Every number in docs/results.md comes from a stored run; nothing is typed by hand. A stored run is one JSON file
``docs/runs/NAME.json`` written by ``scripts/store_runs.py NAME`` (``make runs``), which runs the run's commands
(the ``lft`` command a user runs) into ``out/runs/`` and copies what they wrote, with its provenance::

    {"run": NAME, "kind": "demo" | "bench" | "sequence" | "calibration_seeds" | "twin_compare" | "study" | ...,
     "provenance": {"commands": [...], "commit": "...", "dirty": false, "date": "...",
                    "machine": {"cpus": 2, "platform": "...", "load_average": [1.0, 1.2, 1.5]}, "wall_s": 120.5},
     "data": {...}}

``data`` is the run's own JSON: ``report.json`` of ``lft demo`` / ``lft run``; the ``--json`` file of ``lft bench``;
``report`` (``report.json``) and ``effect`` (``effect.json``, or null) of ``lft render``; ``calibration_errors.json``
of ``lft calibrate seeds``; ``twin_compare.json`` of ``benchmarks/twin/compare.py``; ``study.json`` of
``lft study``.

:data:`RUNS` lists the runs that results.md carries, in order, with the commands that reproduce each; a run with no
file gets the line "not stored yet". A file that is not valid JSON or lacks a field its table needs stops the
generator with one error naming the file and the field (:class:`ResultsError`).
"""

from __future__ import annotations

import json
import sys
from dataclasses import dataclass
from pathlib import Path

from lftransfer.reports.results_demo import demo_tables
from lftransfer.reports.results_format import (db, fixed, median_p95, num, resolution_text, surface_solve_text,
                                                table)
from lftransfer.reports.results_live import (live_fps_tables, paired_tables, profile_tables,
                                             simulator_places_tables, soak_tables)
from lftransfer.reports.results_interfaces import interfaces_calibration_tables, interfaces_tables
from lftransfer.reports.results_occlusion import occlusion_tables
from lftransfer.reports.results_probe import probe_tables
from lftransfer.reports.results_study import study_tables

__all__ = ["Run", "RUNS", "ResultsError", "StoredRun", "load_run", "load_store", "render_results", "main"]

NOT_STORED = "not stored yet: run `make runs`"


@dataclass(frozen=True)
class Run:
    """A run that docs/results.md carries.

    Attributes:
        name: the stored file's stem (``docs/runs/NAME.json``) and ``scripts/store_runs.py``'s name for it.
        kind: which tables it gives (``demo``, ``bench``, ``sequence``, ``calibration_seeds``, ``twin_compare``).
        title: the section's heading.
        commands: the commands that reproduce it, in order (each an argument list, as typed).
        files: what the run writes that is stored: key in ``data`` -> path (for one file, key ``""``: the file
            is ``data`` itself).
        quick: cheap enough to store on a small machine (quarter resolution).
        needs: runs whose outputs its commands read (their calibration), stored first.
    """

    name: str
    kind: str
    title: str
    commands: tuple[tuple[str, ...], ...]
    files: tuple[tuple[str, str], ...]
    quick: bool = False
    needs: tuple[str, ...] = ()

    @property
    def command_line(self) -> str:
        return " && ".join(" ".join(c) for c in self.commands)


def _seq(name: str, title: str, scene: str, *, quick: bool, calibrate: tuple[str, ...] | None,
         calibration: str | None, render: tuple[str, ...], needs: tuple[str, ...] = ()) -> Run:
    out = f"out/runs/{name}"
    cmds: list[tuple[str, ...]] = []
    if calibrate is not None:
        cmds.append(calibrate)
    cmds.append(("lft", "render", scene, *(("--quick",) if quick else ()), *render,
                 *(("--calibration", calibration) if calibration else ()), "--out", out))
    return Run(name, "sequence", title, tuple(cmds),
               (("report", f"{out}/report.json"), ("effect", f"{out}/effect.json")), quick=quick, needs=needs)


_TURNS = ("turns25", ("--simulator-share", "0.25", "--simulator-threads", "2"))
SIMULATOR_PLACES = (("thread", ("--simulator", "thread")), ("nice0", ("--simulator-nice", "0")),
                    ("nice3", ("--simulator-nice", "3")), ("nice7", ()), ("nice10", ("--simulator-nice", "10")), _TURNS)
"""The places the simulator is measured at beside the decoupled loop (:func:`simulator_places_tables`): a name and
the bench's options."""
SIMULATOR_PLACES_FULL = (("nice7", ()), _TURNS)
"""The same at the paper's resolution: side by side (the default) and in turns."""

RUNS: tuple[Run, ...] = (
    Run("demo", "demo", "Fig. 4 at the paper's resolution (`lft demo`)",
        (("lft", "demo", "--out", "out/runs/demo"),), (("", "out/runs/demo/report.json"),)),
    Run("demo_quick", "demo", "Fig. 4 at quarter resolution (`lft demo --quick`)",
        (("lft", "demo", "--quick", "--out", "out/runs/demo_quick"),),
        (("", "out/runs/demo_quick/report.json"),), quick=True),
    Run("demo_quick_quiet", "demo", "Fig. 4 at quarter resolution with a quiet reference (`lft run fig4 --quick "
        "--quiet-reference`)",
        (("lft", "run", "fig4", "--quick", "--quiet-reference", "--out", "out/runs/demo_quick_quiet"),),
        (("", "out/runs/demo_quick_quiet/report.json"),), quick=True),
    Run("occlusion_quick", "occlusion", "A real post in front of a synthetic cube, quarter resolution "
        "(`lft run occlusion --quick --composite depth`)",
        (("lft", "run", "occlusion", "--quick", "--composite", "depth", "--out", "out/runs/occlusion_quick"),),
        (("", "out/runs/occlusion_quick/report.json"),), quick=True),
    Run("occlusion_rod_quick", "occlusion", "A thin real rod in front of a synthetic cube, quarter resolution "
        "(`lft run occlusion_rod --quick --composite depth`)",
        (("lft", "run", "occlusion_rod", "--quick", "--composite", "depth", "--out", "out/runs/occlusion_rod_quick"),),
        (("", "out/runs/occlusion_rod_quick/report.json"),), quick=True),
    Run("occlusion_reverse_quick", "occlusion", "A synthetic ball in front of the real block, seen from behind the "
        "array's plane, quarter resolution (`lft run occlusion_reverse --quick`, the depth composite)",
        (("lft", "run", "occlusion_reverse", "--quick", "--out", "out/runs/occlusion_reverse_quick"),),
        (("", "out/runs/occlusion_reverse_quick/report.json"),), quick=True),
    _seq("occlusion_crossing_quick", "A real post crossing in front of a synthetic cube, quarter resolution",
         "occlusion_crossing", quick=True, calibrate=None, calibration=None,
         render=("--composite", "depth", "--verify-every", "6", "--no-floor")),
    _seq("occlusion_passing_quick", "A real ball rolling across in front of a synthetic cube, quarter resolution",
         "occlusion_passing", quick=True, calibrate=None, calibration=None,
         render=("--composite", "depth", "--verify-every", "6", "--no-floor")),
    Run("probe_quick", "probe", "A light probe: the room's light on the synthetic cube, against one point light, "
        "quarter resolution (`lft run probe --quick`, then `--direct-light point` with its calibration)",
        (("lft", "run", "probe", "--quick", "--out", "out/runs/probe_quick"),
         ("lft", "run", "probe", "--quick", "--direct-light", "point", "--calibration",
          "out/runs/probe_quick/calibration.json", "--out", "out/runs/probe_point_quick")),
        (("probe", "out/runs/probe_quick/report.json"), ("point", "out/runs/probe_point_quick/report.json")),
        quick=True),
    Run("interfaces_quick", "interfaces", "Two and three interfaces around the real block (`lft run corner`, "
        "`lft run enclosure`), against Fig. 4, all with the true rig models and a quiet reference, quarter resolution",
        tuple(("lft", "run", name, "--quick", "--rig-model", "oracle", "--quiet-reference", "--out",
               f"out/runs/interfaces_{name}_quick") for name in ("fig4", "corner", "enclosure")),
        tuple((name, f"out/runs/interfaces_{name}_quick/report.json") for name in ("fig4", "corner", "enclosure")),
        quick=True),
    Run("interfaces_calibrated_quick", "interfaces", "Two and three interfaces around the real block, each interface "
        "calibrated from its images into one world frame, against Fig. 4 calibrated alike; a quiet reference, quarter "
        "resolution",
        tuple(("lft", "run", name, "--quick", "--quiet-reference", "--out",
               f"out/runs/interfaces_{name}_calibrated_quick") for name in ("fig4", "corner", "enclosure")),
        tuple((name, f"out/runs/interfaces_{name}_calibrated_quick/report.json")
              for name in ("fig4", "corner", "enclosure")),
        quick=True),
    Run("interfaces_calibration", "interfaces_calibration", "Each interface of the corner and the enclosure "
        "calibrated from its images at the paper's resolution (`lft calibrate corner`, `lft calibrate enclosure`)",
        tuple(("lft", "calibrate", name, "--out", f"out/runs/interfaces_calibration/{name}/calibration.json")
              for name in ("corner", "enclosure")),
        tuple((name, f"out/runs/interfaces_calibration/{name}/calibration_errors.json")
              for name in ("corner", "enclosure"))),
    Run("oracle", "demo", "Fig. 4 with the hidden true rig and light (the oracle, no calibration)",
        (("lft", "run", "fig4", "--rig-model", "oracle", "--compare-models", "--out", "out/runs/oracle"),),
        (("", "out/runs/oracle/report.json"),)),
    Run("bench_quick", "bench", "The live step at quarter resolution (`lft bench --quick`)",
        (("lft", "bench", "--quick", "--json", "out/runs/bench_quick.json"),),
        (("", "out/runs/bench_quick.json"),), quick=True),
    Run("simulator_places_quick", "simulator_places",
        "Where the simulator renders beside the decoupled loop, quarter resolution (`lft bench --quick --live` with "
        "`--simulator thread`, then its own process at `--simulator-nice` 0, 3, 7 (the default) and 10, then in "
        "turns with the frames, `--simulator-share 0.25 --simulator-threads 2`)",
        tuple(("lft", "bench", "--quick", "--live", "--no-peer", "--no-accuracy", *place,
               "--json", f"out/runs/simulator_{name}.json") for name, place in SIMULATOR_PLACES),
        tuple((name, f"out/runs/simulator_{name}.json") for name, _place in SIMULATOR_PLACES), quick=True),
    Run("simulator_places", "simulator_places",
        "Where the simulator renders beside the decoupled loop, the paper's resolution (`lft bench --live`: side by "
        "side at nice 7, the default, then in turns with the frames, `--simulator-share 0.25 --simulator-threads 2`)",
        tuple(("lft", "bench", "--live", "--no-peer", "--no-accuracy", "--calibration",
               "out/runs/demo/calibration.json", *place, "--json", f"out/runs/simulator_full_{name}.json")
              for name, place in SIMULATOR_PLACES_FULL),
        tuple((name, f"out/runs/simulator_full_{name}.json") for name, _place in SIMULATOR_PLACES_FULL),
        needs=("demo",)),
    Run("bench", "bench", "The live step at the paper's resolution, still scene (`lft bench`)",
        (("lft", "bench", "--no-peer", "--calibration", "out/runs/demo/calibration.json",
          "--json", "out/runs/bench.json"),), (("", "out/runs/bench.json"),), needs=("demo",)),
    Run("bench_live", "bench", "The live step at the paper's resolution, a moving cube (`lft bench --live`)",
        (("lft", "bench", "--live", "--no-peer", "--calibration", "out/runs/demo/calibration.json",
          "--json", "out/runs/bench_live.json"),), (("", "out/runs/bench_live.json"),), needs=("demo",)),
    Run("bench_live_box", "bench",
        "The live step at the paper's resolution, a moving cube, box light field (`--projection box`)",
        (("lft", "bench", "--live", "--projection", "box", "--no-peer", "--calibration",
          "out/runs/demo/calibration.json", "--json", "out/runs/bench_live_box.json"),),
        (("", "out/runs/bench_live_box.json"),), needs=("demo",)),
    Run("paired_84066a4", "paired", "The pipeline against commit 84066a4 (BLAS threads unbounded), paired: "
        "`scripts/paired_bench.py`",
        (("python", "scripts/paired_bench.py", "--against", "84066a4", "--with", "HEAD", "--json",
          "out/runs/paired_84066a4.json"),), (("", "out/runs/paired_84066a4.json"),)),
    Run("paired_beed803", "paired", "The pipeline against commit beed803 (before the solve's products one column "
        "at a time and the primary rays culled once while nothing moves), paired",
        (("python", "scripts/paired_bench.py", "--against", "beed803", "--with", "HEAD", "--rounds", "3", "--json",
          "out/runs/paired_beed803.json"),), (("", "out/runs/paired_beed803.json"),)),
    Run("paired_8184fa7", "paired", "The pipeline against commit 8184fa7 (before the regression), paired",
        (("python", "scripts/paired_bench.py", "--against", "8184fa7", "--with", "HEAD", "--json",
          "out/runs/paired_8184fa7.json"),), (("", "out/runs/paired_8184fa7.json"),)),
    _seq("fig5_quick", "Fig. 5 at quarter resolution: the planet's shadow on the head", "fig5", quick=True,
         calibrate=("lft", "calibrate", "rig", "fig5", "--quick", "--out",
                    "out/runs/fig5_quick_cal/calibration.json"),
         calibration="out/runs/fig5_quick_cal/calibration.json", render=("--verify-every", "4")),
    _seq("fig6_quick", "Fig. 6 at quarter resolution: the photograph's reflection in the bowl", "fig6",
         quick=True, calibrate=None, calibration=None, render=("--verify-every", "12")),
    _seq("fig6_quick_quiet", "Fig. 6 at quarter resolution, frame 12 against a quiet reference", "fig6", quick=True,
         calibrate=None, calibration=None, render=("--frames", "13", "--verify-every", "12", "--quiet-reference")),
    _seq("fig1b_quick", "Fig. 1b at quarter resolution: the gold frame, with a quiet reference", "fig1b", quick=True,
         calibrate=None, calibration=None, render=("--verify-every", "16", "--quiet-reference")),
    _seq("fig5", "Fig. 5 at the paper's resolution", "fig5", quick=False,
         calibrate=("lft", "calibrate", "rig", "fig5", "--out", "out/runs/fig5_cal/calibration.json"),
         calibration="out/runs/fig5_cal/calibration.json",
         render=("--frames", "43", "--verify-every", "6", "--gt-spp", "128")),
    _seq("fig6", "Fig. 6 at the paper's resolution", "fig6", quick=False, calibrate=None,
         calibration="out/runs/demo/calibration.json", render=("--verify-every", "12", "--gt-spp", "128"),
         needs=("demo",)),
    _seq("fig1b", "Fig. 1b at the paper's resolution", "fig1b", quick=False, calibrate=None,
         calibration="out/runs/demo/calibration.json", render=("--verify-every", "12", "--gt-spp", "128"),
         needs=("demo",)),
    _seq("corner_quick", "The corner live at quarter resolution: two interfaces calibrated, the lamp's light on the "
         "block through the second", "corner", quick=True, calibrate=None, calibration=None,
         render=("--frames", "4", "--verify-every", "3", "--quiet-reference")),
    _seq("enclosure_quick", "The enclosure live at quarter resolution: three interfaces calibrated, the lamp's light on "
         "the block through the second", "enclosure", quick=True, calibrate=None, calibration=None,
         render=("--frames", "4", "--verify-every", "3", "--quiet-reference")),
    _seq("fig5_quick_decoupled", "Fig. 5 at quarter resolution, the decoupled loop: the cost of stale captures",
         "fig5", quick=True, calibrate=None, calibration="out/runs/fig5_quick_cal/calibration.json",
         render=("--verify-every", "4", "--loop", "decoupled"), needs=("fig5_quick",)),
    Run("live_fps_quick", "live_fps", "`lft live` as a page sees it, quarter resolution: decoupled against --sync",
        (("python", "scripts/measure_live_fps.py", "--quick", "--seconds", "60", "--json",
          "out/runs/live_fps_quick.json"),), (("", "out/runs/live_fps_quick.json"),), quick=True),
    Run("live_fps_quick_drag", "live_fps", "`lft live` as a page sees it, quarter resolution, the decoupled loop "
        "with an edit every 1/30 s (a slider dragged faster than the page renders)",
        (("python", "scripts/measure_live_fps.py", "--quick", "--seconds", "60", "--loop", "decoupled",
          "--edit-every", "0.0333", "--json", "out/runs/live_fps_quick_drag.json"),),
        (("", "out/runs/live_fps_quick_drag.json"),), quick=True),
    Run("live_fps", "live_fps", "`lft live` as a page sees it, the paper's resolution: decoupled against --sync",
        (("python", "scripts/measure_live_fps.py", "--seconds", "90", "--calibration",
          "out/runs/demo/calibration.json", "--json", "out/runs/live_fps.json"),), (("", "out/runs/live_fps.json"),),
        needs=("demo",)),
    Run("soak_live_quick", "soak", "A 10-minute soak of `lft live` (decoupled, quarter resolution, an edit a second)",
        (("python", "scripts/soak_live.py", "--quick", "--minutes", "10", "--json", "out/runs/soak_live_quick.json"),),
        (("", "out/runs/soak_live_quick.json"),), quick=True),
    Run("profile", "profile", "The pipeline profiled at the paper's resolution (py-spy), without the simulator",
        (("python", "scripts/profile_pipeline.py", "--py-spy", "--calibration", "out/runs/demo/calibration.json",
          "--json", "out/runs/profile.json"),), (("", "out/runs/profile.json"),), needs=("demo",)),
    Run("profile_before", "profile", "The same profile before issue 30's changes to the stages (commit 1a07f36)",
        (("git", "worktree", "add", "-f", "--detach", "out/runs/src_1a07f36", "1a07f36"),
         ("python", "scripts/profile_pipeline.py", "--py-spy", "--src", "out/runs/src_1a07f36", "--calibration",
          "out/runs/demo/calibration.json", "--json", "out/runs/profile_before.json")),
        (("", "out/runs/profile_before.json"),), needs=("demo",)),
    Run("study_pitch", "study", "The rig designer: Figs. 4 and 5 against the lens pitch, with the fidelity floor "
        "(`lft study pitch`, quarter resolution)",
        (("lft", "study", "pitch", "--out", "out/runs/study_pitch"),), (("", "out/runs/study_pitch/study.json"),),
        quick=True),
    Run("calibration_seeds", "calibration_seeds",
        "Calibration accuracy over five hidden truths (`lft calibrate seeds`)",
        (("lft", "calibrate", "seeds", "--seeds", "1,2,3,4,5", "--out", "out/runs/calibration_seeds"),),
        (("", "out/runs/calibration_seeds/calibration_errors.json"),)),
    Run("twin_compare", "twin_compare",
        "Fig. 4 through the hardware path (the device twin) against the in-process rig",
        (("python", "benchmarks/twin/compare.py", "--out", "out/runs/twin_compare"),),
        (("", "out/runs/twin_compare/twin_compare.json"),)),
)

RUN_BY_NAME = {r.name: r for r in RUNS}


class ResultsError(ValueError):
    """A stored run that cannot be read: the message names the file and the field."""


@dataclass(frozen=True)
class StoredRun:
    """One ``docs/runs/NAME.json``: its path, its kind, its provenance and its data."""

    path: Path
    name: str
    kind: str
    provenance: dict
    data: dict

    def need(self, *keys: str | int, within: object = None):
        """``data[k0][k1]...`` (or ``within[k0]...``); :class:`ResultsError` naming the file and the field when
        one is missing."""
        node = self.data if within is None else within
        trail = "data" if within is None else ""
        for key in keys:
            trail = f"{trail}[{key}]" if isinstance(key, int) else (f"{trail}.{key}" if trail else str(key))
            try:
                node = node[key]
            except (KeyError, IndexError, TypeError):
                raise ResultsError(f"{self.path}: missing field '{trail}' (a {self.kind} run needs it)") from None
        return node


PROVENANCE_FIELDS = ("commands", "commit", "date", "machine", "wall_s")
KINDS = ("demo", "bench", "sequence", "calibration_seeds", "twin_compare", "live_fps", "soak", "profile", "study",
         "occlusion", "probe", "paired", "simulator_places", "interfaces", "interfaces_calibration")


def load_run(path: str | Path) -> StoredRun:
    """Read and check one stored run.

    Raises:
        ResultsError: not valid JSON, or a field missing (named with the file).
    """
    path = Path(path)
    try:
        raw = json.loads(path.read_text(encoding="utf-8"))
    except json.JSONDecodeError as exc:
        raise ResultsError(f"{path}: not valid JSON: {exc}") from None
    except OSError as exc:
        raise ResultsError(f"{path}: cannot read it: {exc}") from None
    if not isinstance(raw, dict):
        raise ResultsError(f"{path}: expected a JSON object with 'kind', 'provenance' and 'data'")
    for key in ("kind", "provenance", "data"):
        if key not in raw:
            raise ResultsError(f"{path}: missing field '{key}'")
    if raw["kind"] not in KINDS:
        raise ResultsError(f"{path}: field 'kind' is {raw['kind']!r}, expected one of {', '.join(KINDS)}")
    prov = raw["provenance"]
    if not isinstance(prov, dict):
        raise ResultsError(f"{path}: field 'provenance' must be an object")
    for key in PROVENANCE_FIELDS:
        if key not in prov:
            raise ResultsError(f"{path}: missing field 'provenance.{key}'")
    if not isinstance(raw["data"], dict):
        raise ResultsError(f"{path}: field 'data' must be an object")
    return StoredRun(path, raw.get("run", path.stem), raw["kind"], prov, raw["data"])


def load_store(folder: str | Path) -> dict[str, StoredRun]:
    """Every ``*.json`` of the store, by name (the file's stem)."""
    folder = Path(folder)
    if not folder.is_dir():
        raise ResultsError(f"{folder}: no such folder (the store of runs, docs/runs/)")
    return {p.stem: load_run(p) for p in sorted(folder.glob("*.json"))}


def provenance_lines(run: Run | None, stored: StoredRun) -> list[str]:
    """The lines under a section's heading: the command, the commit, the date, the machine, the wall time."""
    p = stored.provenance
    commands = p["commands"]
    if isinstance(commands, str):
        commands = [commands]
    line = " && ".join(str(c) for c in commands)
    commit = str(p["commit"] or "unknown")
    if p.get("dirty"):
        commit += " (with uncommitted changes in the working tree)"
    machine = p["machine"]
    if isinstance(machine, dict):
        parts = []
        if machine.get("cpus") is not None:
            parts.append(f"{machine['cpus']} CPUs")
        if machine.get("platform"):
            parts.append(str(machine["platform"]))
        if machine.get("load_average"):
            parts.append("load average " + " / ".join(num(x, 2) for x in machine["load_average"])
                         + " (1, 5, 15 min) at the start")
        if machine.get("gpu"):
            parts.append(str(machine["gpu"]))
        machine = ", ".join(parts) or "unknown"
    wall = p["wall_s"]
    out = [f"Reproduce: `{line}`"]
    if run is not None:
        out[0] += f" (stored by `python scripts/store_runs.py {run.name}`)"
    out += ["", f"Commit {commit}; date {p['date']}; machine: {machine}; "
            f"wall time {fixed(wall, 0, ' s') if wall is not None else 'not recorded'}."]
    if p.get("note"):
        out += ["", str(p["note"])]
    return out + [""]


# --------------------------------------------------------------------------------------------------- kinds

def _spread(v) -> str:
    if isinstance(v, dict):
        return f"{fixed(v.get('median'), 1)} ({fixed(v.get('min'), 1)} to {fixed(v.get('max'), 1)})"
    return fixed(v, 1)


def bench_tables(s: StoredRun) -> list[str]:
    d = s.data
    for key in ("pipeline_iteration_ms", "pipeline_fps", "step_fps", "stages_ms", "floor_ms",
                "iteration_over_floor"):
        s.need(key)
    settings = d.get("settings") or {}
    out: list[str] = []
    if settings.get("resolution"):
        res = dict(settings["resolution"])
        res["angular_samples"] = settings.get("angular_samples")
        if res["angular_samples"] is None:
            del res["angular_samples"]
        named = ", ".join(f"{k} {settings[k]}" for k in ("lighting_model", "reconstruction", "projection",
                                                          "rig_model", "variant", "iterations")
                          if settings.get(k) is not None)
        renderer = settings.get("renderer")
        if isinstance(renderer, dict):
            named += f", renderer {renderer.get('used')}"
        moving = settings.get("animated") or d.get("frames_moved")
        out += [f"Resolution: {resolution_text(res)}. Settings: {named}; "
                f"{'a synthetic object moving in every frame' if moving else 'a still scene'}.", ""]
    pi = d.get("pipeline_iteration") or {}
    rows = [["`pipeline_iteration_ms` (median; min to max)",
             f"{fixed(d['pipeline_iteration_ms'], 1)} ({fixed(pi.get('min'), 1)} to {fixed(pi.get('max'), 1)})"],
            ["frames per second: pipeline / whole step (`pipeline_fps`, `step_fps`)",
             f"{num(d['pipeline_fps'])} / {num(d['step_fps'])}"]]
    rows += [[f"stage `{k}`, ms (median; min to max)", _spread(v)] for k, v in d["stages_ms"].items()]
    if "capture_ms" in d:
        rig = d.get("rig_stages_ms") or {}
        detail = ", ".join(f"{k} {fixed(v.get('median') if isinstance(v, dict) else v, 1)}" for k, v in rig.items())
        rows.append(["`capture_ms` (the simulator's capture, not in the pipeline)",
                     fixed(d["capture_ms"], 1) + (f" ({detail})" if detail else "")])
    for key, label in (("unstaged_ms", "`unstaged_ms` (in no stage)"), ("step_total_ms", "`step_total_ms`")):
        if key in d:
            rows.append([label, fixed(d[key], 1)])
    floor = d.get("floor") or {}
    rays = floor.get("rays")
    rows.append(["`floor_ms` (the step's rays cast once)",
                 fixed(d["floor_ms"], 1) + (f" ({' + '.join(f'{r:,}' for r in rays)} rays)" if rays else "")])
    rows.append(["`iteration_over_floor`", num(d["iteration_over_floor"])])
    if isinstance(d.get("surface_solve"), dict):
        rows.append(["the projection's solve against the measured surface (`surface_solve`, in `encode`)",
                     surface_solve_text(d["surface_solve"])])
    for loop, lat in (d.get("latency_ms") or {}).items():
        if isinstance(lat, dict):
            rows.append([f"motion to composite / to its light, ms, median (95 %) ({loop} loop)",
                         f"{median_p95(lat.get('view'))} / {median_p95(lat.get('light'))}"])
    if isinstance(d.get("decoupled"), dict):
        rows += _decoupled_rows(d["decoupled"])
    fve = d.get("fast_vs_exact")
    rows.append(["`fast_vs_exact`: PSNR all pixels / the synthetic objects'",
                 f"{db(fve.get('psnr_db'))} / {db(fve.get('psnr_objects_db'))}" if isinstance(fve, dict)
                 else "not run"])
    peer = d.get("peer")
    if isinstance(peer, dict):
        bound = "" if peer.get("reached_target") else " (the peer did not reach our RMSE: a lower bound)"
        rows.append(["peer: Mitsuba `path`, light field job, point model (`peer`)",
                     f"{fixed(peer.get('peer_ms'), 1)} ms at {peer.get('peer_spp')} spp against ours "
                     f"{fixed(peer.get('ours_ms'), 1)} ms: ratio {num(peer.get('ratio'))}{bound}"])
    else:
        rows.append(["peer (Mitsuba `path`)", "not run"])
    for key, label in (("cache_vertices", "`cache_vertices`"), ("peak_rss_mb", "`peak_rss_mb`"),
                       ("calibration_s", "`calibration_s` (calibrating first)")):
        if key in d:
            rows.append([label, num(d[key]) if key != "calibration_s" else fixed(d[key], 1)])
    load = (settings.get("machine") or {}).get("load_average")
    if load:
        rows.append(["load average at the end (1, 5, 15 min)", " / ".join(num(x, 2) for x in load)])
    out += table(["quantity", "value"], rows)
    if d.get("notes"):
        out += [f"- {n}" for n in d["notes"]] + [""]
    return out


def _decoupled_rows(dec: dict) -> list[list[str]]:
    """The bench table's rows of ``lft bench --live``'s decoupled run (``decoupled`` of its JSON)."""
    rows = [["decoupled loop: frames per second with the captures beside them (`decoupled.render_fps`)",
             f"{num(dec.get('render_fps'))} ({dec.get('frames')} frames, {fixed(dec.get('frame_ms'), 0)} ms "
             f"per frame)"]]
    if dec.get("render_fps_alone") is not None:
        rows.append(["decoupled loop: frames per second with the captures held, the renderer alone "
                     "(`decoupled.render_fps_alone`); the share kept beside the simulator "
                     "(`rate_with_simulator`); cores busy with and without it",
                     f"{num(dec['render_fps_alone'])}; {fixed(100 * dec['rate_with_simulator'], 0)} %; "
                     f"{fixed(dec.get('cores_busy'), 2)} and {fixed(dec.get('cores_busy_alone'), 2)}"])
    sim = dec.get("simulator")
    if sim is not None:
        rows.append(["decoupled loop: where the simulator rendered its captures (`decoupled.simulator`), its cores "
                     "busy (`simulator_cores_busy`)",
                     f"its own process, {sim['threads']} thread(s), nice {sim['nice']}; "
                     f"{fixed(dec.get('simulator_cores_busy'), 2)}" if sim.get("where") == "process" else
                     "the loop's process (counted in its cores busy)"])
    age = dec.get("capture_age_s") or {}
    rows.append(["decoupled loop: captures per second, capture age (median, largest)",
                 f"{num(dec.get('capture_hz'))}; {fixed(age.get('median'), 2)} s, {fixed(age.get('max'), 2)} s"])
    return rows


def sequence_tables(s: StoredRun) -> list[str]:
    report = s.need("report")
    frames = s.need("report", "frames")
    summary = report.get("summary") or {}
    out: list[str] = []
    keys = [k for k in ("frames", "median_frame_s", "transfer_fps", "psnr_objects_db_min", "psnr_objects_db_max",
                        "cross_transfer_rel_error_min", "cross_transfer_rel_error_max", "cross_gt_noise_rel_max",
                        "psnr_hidden_db_min", "psnr_hidden_db_max", "psnr_hidden_over_db_min",
                        "psnr_hidden_over_db_max", "fidelity_floor_min", "fidelity_floor_max", "transfer_over_floor_min",
                        "transfer_over_floor_max", "reference_spp_min", "reference_spp_max",
                        "reference_noise_over_error_max", "references_met", "references", "stale_captures",
                        "captures_used", "capture_behind_s_median", "capture_behind_s_max",
                        "capture_age_s_median") if k in summary]
    settings = ", ".join(f"{k} {report[k]}" for k in ("mode", "loop", "rig_model", "renderer", "projection",
                                                      "variant")
                         if report.get(k) is not None)
    if settings:
        out += [f"Settings: {settings}.", ""]
    if keys:
        out += table(["quantity", "value"], [[f"`{k}`", num(summary[k])] for k in keys])
    verified = [f for f in frames if isinstance(f, dict) and f.get("metrics")]
    if verified:
        cols = ("psnr_objects_db", "psnr_hidden_db", "psnr_hidden_over_db", "cross_transfer_rel_error", "cross_gt_noise_rel", "cross_synthetic_rel_error",
                "cross_synthetic_gt_noise_rel", "cross_real_rel_error", "cross_real_gt_noise_rel", "real_floor",
                "synthetic_floor", "floor_transfer", "transfer_over_floor", "reference_spp",
                "reference_noise_over_error")
        present = [c for c in cols if any(c in f["metrics"] for f in verified)]
        out += ["Verified frames (each against its own path-traced ground truth; `..._gt_noise_rel` is the ground "
                "truth's own noise on the same term; the floors and `floor_transfer`, the frame scored as they are, "
                "are noise-corrected, docs/architecture.md \"The fidelity floor\"; `reference_...`: the quiet "
                "reference's samples per pixel and its noise over the error; `psnr_hidden_...`: over the pixels "
                "where a real object hides a synthetic one, the frame's composite and the over operator's):", ""]
        out += table(["frame", "t, s", *(f"`{c}`" for c in present)],
                     [[num(f.get("index")), fixed(f.get("time_s"), 2),
                       *((db if c.endswith("_db") else num)(f["metrics"].get(c)) for c in present)]
                      for f in verified])
    effect = s.data.get("effect")
    if isinstance(effect, dict):
        points = s.need("effect", "points")
        kind = effect.get("kind")
        names = (("added_radiance", "added radiance, W m^-2 sr^-1", 1.0),) if kind == "reflection" else (
            ("contrast", "contrast", 1.0), ("penumbra_m", "penumbra, mm", 1000.0), ("area_m2", "area, cm^2", 1e4))
        scale = lambda v, k: None if v is None else v * k  # noqa: E731
        out += [f"The effect (`effect.json`: {kind} on `{effect.get('on')}` by `{effect.get('by')}`), "
                "transfer / ground truth:", ""]
        out += table(["frame", "distance, mm", *(label for _, label, _ in names)],
                     [[num(p.get("index")), fixed(scale(p.get("distance_m"), 1000.0), 1),
                       *(f"{num(scale((p.get('transfer') or {}).get(n), k))} / "
                         f"{num(scale((p.get('truth') or {}).get(n), k))}" for n, _, k in names)]
                      for p in points])
        worst = effect.get("worst_relative_error") or {}
        trend = effect.get("same_trend") or {}
        if worst:
            out += table(["measure", "worst relative error", "same trend (fraction of steps)", "bound"],
                         [[n, num(worst.get(n)), num(trend.get(n)), num(effect.get("agreement_bound"))]
                          for n in worst])
    elif "effect" in s.data:
        out += ["The scene has no `[effect]` (no effect.json).", ""]
    return out


def calibration_seeds_tables(s: StoredRun) -> list[str]:
    seeds = s.need("seeds")
    summary = s.need("summary")
    names = list(seeds)
    out: list[str] = []
    if s.data.get("resolution"):
        out += [f"Resolution: {resolution_text(s.data['resolution'])}.", ""]
    keys: list[str] = []
    for errors in seeds.values():
        keys += [k for k in errors if k not in keys]
    rows = []
    for k in keys:
        q = summary.get(k) or {}
        met = q.get("met")
        rows.append([f"`{k}`", *(num(seeds[n].get(k)) for n in names), num(q.get("worst")), num(q.get("target")),
                     "-" if met is None else ("met" if met else "NOT met")])
    out += table(["quantity", *(f"seed {n}" for n in names), "worst", "target", "every seed"], rows)
    return out


TWIN_ROWS = (("cross_transfer_rel_error", "cross-transfer error"), ("psnr_objects_db", "psnr_objects_db"),
             ("psnr_db", "psnr_db"), ("cross_gt_noise_rel", "ground truth's noise on the cross term"),
             ("seconds_per_live_frame", "seconds per live frame"))


def twin_tables(s: StoredRun) -> list[str]:
    inproc, hw = s.need("inproc"), s.need("hardware")
    for side in ("inproc", "hardware"):
        s.need(side, "cross_transfer_rel_error")
    d = s.data
    out = [f"Scene {d.get('scene')}{' at quarter resolution' if d.get('quick') else ''}, ground truth "
           f"{d.get('gt_spp')} samples per pixel, {d.get('live_frames')} live frames.", ""]
    f = lambda k: db if k.endswith("_db") else num  # noqa: E731
    rows = [[label, f(k)(inproc.get(k)), f(k)(hw.get(k))] for k, label in TWIN_ROWS]
    for k in (inproc.get("calibration") or {}):
        rows.append([f"calibration: `{k}`", num(inproc["calibration"].get(k)),
                     num((hw.get("calibration") or {}).get(k))])
    rows.append(["calibration + transfer (`lft run`), s", fixed(d.get("inproc_run_s"), 0),
                 fixed(d.get("hardware_run_s"), 0)])
    out += table(["", "in-process rig", "hardware path (twin)"], rows)
    a, b = inproc.get("cross_transfer_rel_error"), hw.get("cross_transfer_rel_error")
    if a is not None and b is not None:
        out += [f"The two cross-transfer errors are {num(abs(a - b), 2)} apart.", ""]
    if d.get("latency"):
        out += ["Latency calibration against configured latencies (`lft calibrate latency`):", ""]
        out += table(["configured latency", "jitter", "delay: median", "delay: max", "LF camera frame",
                      "latency read (median - frame / 2)", "settle_s written"],
                     [[fixed(r.get("configured_ms"), 0, " ms"), fixed(r.get("jitter_ms"), 0, " ms"),
                       fixed(r.get("median_ms"), 0, " ms"), fixed(r.get("max_ms"), 0, " ms"),
                       fixed(r.get("frame_ms"), 0, " ms"), fixed(r.get("latency_ms"), 0, " ms"),
                       fixed(r.get("settle_ms"), 0, " ms")] for r in d["latency"]])
    return out


TABLES = {"demo": demo_tables, "bench": bench_tables, "sequence": sequence_tables,
          "calibration_seeds": calibration_seeds_tables, "twin_compare": twin_tables,
          "live_fps": live_fps_tables, "soak": soak_tables, "profile": profile_tables,
          "study": lambda s: study_tables(s.data),
          "occlusion": lambda s: demo_tables(s) + occlusion_tables(s),
          "probe": probe_tables, "paired": paired_tables, "interfaces": interfaces_tables,
          "interfaces_calibration": interfaces_calibration_tables,
          "simulator_places": lambda s: simulator_places_tables(s, list(s.data))}

GROUPS = (("Fig. 4: the demo", ("demo", "demo_quick", "demo_quick_quiet", "oracle")),
          ("The live step: `lft bench`", ("bench_quick", "simulator_places_quick", "bench", "bench_live",
                                          "simulator_places", "bench_live_box",
                                          "paired_84066a4", "paired_8184fa7",
                                          "paired_beed803")),
          ("The live page: `lft live`", ("live_fps_quick", "live_fps_quick_drag", "live_fps", "soak_live_quick",
                                          "profile_before", "profile")),
          ("Sequences: Figs. 5, 6 and 1b", ("fig5_quick", "fig5_quick_decoupled", "fig6_quick", "fig6_quick_quiet",
                                            "fig1b_quick", "fig5", "fig6", "fig1b")),
          ("Occlusion: real objects in front of synthetic ones, and the reverse",
           ("occlusion_quick", "occlusion_rod_quick", "occlusion_crossing_quick", "occlusion_passing_quick",
            "occlusion_reverse_quick")),
          ("A light probe: the room's light as direct light", ("probe_quick",)),
          ("Several light field interfaces around the real objects",
           ("interfaces_quick", "interfaces_calibrated_quick", "interfaces_calibration", "corner_quick",
            "enclosure_quick")),
          ("The fidelity floor against the lens pitch: the rig designer", ("study_pitch",)),
          ("Calibration over hidden truths", ("calibration_seeds",)),
          ("The hardware path on the device twin", ("twin_compare",)))

HEADER = """\
# Measured results

<!-- generated by `make results` (python -m lftransfer.reports.results docs/runs docs/results.md): do not edit -->

Every number on this page comes from a stored run in [docs/runs/](runs/): one JSON file per run, holding what the
run wrote (its `report.json`, its `--json` file) and its provenance: the command, the commit, the date, the machine
and the wall time. `make runs` runs the commands again and stores their JSON (`python scripts/store_runs.py NAME`
for one run; `--quick` for the quarter-resolution ones only); `make results` rewrites this page from the store.
What the metrics mean: README.md ("What the numbers mean") and docs/architecture.md ("Verification"). Timings
depend on the machine and on what else runs on it: compare timings of runs made on one machine in one session.
"""


def render_results(store: dict[str, StoredRun]) -> str:
    """The Markdown of docs/results.md from the stored runs."""
    out = [HEADER]
    for heading, names in GROUPS:
        out += [f"## {heading}", ""]
        for name in names:
            run = RUN_BY_NAME[name]
            out += [f"### {run.title}", ""]
            stored = store.get(name)
            if stored is None:
                out += [f"{NOT_STORED} (or `python scripts/store_runs.py {name}`, which runs "
                        f"`{run.command_line}`).", ""]
                continue
            if stored.kind != run.kind:
                raise ResultsError(f"{stored.path}: field 'kind' is {stored.kind!r}, expected {run.kind!r} "
                                   f"for the run {name!r}")
            out += provenance_lines(run, stored)
            out += TABLES[stored.kind](stored)
    others = [s for n, s in store.items() if n not in RUN_BY_NAME]
    if others:
        out += ["## Other stored runs", ""]
        for stored in others:
            out += [f"### {stored.name}", ""] + provenance_lines(None, stored) + TABLES[stored.kind](stored)
    return "\n".join(out).rstrip() + "\n"


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    if len(args) != 2 or args[0] in ("-h", "--help"):
        print("usage: python -m lftransfer.reports.results STORE_DIR OUT.md   (make results: docs/runs docs/results.md)",
              file=sys.stderr)
        return 2
    try:
        text = render_results(load_store(args[0]))
    except ResultsError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    out = Path(args[1])
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(out.name + ".tmp")
    tmp.write_text(text, encoding="utf-8")
    tmp.replace(out)
    print(f"wrote {out} from {len(load_store(args[0]))} stored runs")
    return 0


if __name__ == "__main__":
    sys.exit(main())

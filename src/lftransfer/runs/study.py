"""Studies: scenes x hidden truths x settings -> one table (``lft study STUDY.toml``).

A study file names scenes (built-in names or scene files), hidden-truth seeds of the simulated rig, and settings
(each a name and changes to the scenes' ``[render]`` table, e.g. ``reconstruction = "box"``). Every cell is one
converged N-bounce transfer of a scene on the simulated rig of a seed with a setting, measured against its
path-traced ground truth (:func:`lftransfer.sim.metrics.evaluate`). Example::

    [study]
    title = "Reconstruction across scenes"
    scenes = ["fig4", "spheres.toml"]        # paths are relative to the study file
    truth_seeds = [1, 2]
    rig_model = "oracle"                     # calibrated | nominal | oracle
    bounces = 2
    quick = true                             # every scene at a quarter of its resolution (lft run --quick)

    [[setting]]
    name = "box"
    render = { reconstruction = "box" }

    [[setting]]
    name = "linear"
    render = { reconstruction = "linear" }

A setting may change the rig too (``rig = { angular_samples = 12, projector_bits = 10 }``: any field of the scene's
``[rig]``), and ``array_pitch_mm`` redesigns the lens array: lenslets of that pitch over the scene's array's extent
(rows and columns scaled, the focal length keeping the scene's f-number), the LF camera and the projector scaled
to keep their pixels per lenslet. With ``floor = true`` each cell also finds the fidelity floor
(:mod:`lftransfer.sim.floor`), and a study whose settings all set ``array_pitch_mm`` plots the error and the
floors against the pitch (``pitch.png``): the rig designer (``lft study pitch``, the built-in pitch study).

The work comes in two rounds: first each (scene, seed) pair gets its rig model (calibrated, if asked, once for
every setting) and its ground truth (rendered once, kept in the ground-truth cache); then every cell. Both rounds
run in this process or as tasks on a Ray cluster (:mod:`lftransfer.runs.cluster`), with the same results. Each
finished cell is written at once (``cells/*.json``), so an interrupted study resumes without redoing it. The
output folder gets ``study.json``, ``study.md`` (the table), ``study.png`` (a plot) and ``study.html``.
"""

from __future__ import annotations

import hashlib
import math
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Callable, Optional

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator, model_validator

from lftransfer import choices
from lftransfer.runs.cluster import ClusterSpec, LocalPool, Worker
from lftransfer.runs.run_folder import tracked_run, write_status
from lftransfer.imageio_utils import write_json, write_text
from lftransfer.scenes import SceneError, builtin_scene, builtin_scenes, load_scene, with_overrides
from lftransfer.validation import read_json, read_toml, validation_message

__all__ = ["FLOOR_METRICS", "METRICS", "Study", "StudyCell", "StudyConfig", "StudyError", "StudyResult",
           "StudySetting", "builtin_studies", "builtin_study", "cell_key", "load_study", "redesigned_array",
           "run_study", "write_study_outputs"]

# metric -> (label, unit, lower is better, short label); the cells' columns (lftransfer.sim.metrics.evaluate)
METRICS = {
    "cross_transfer_rel_error": ("cross-transfer error", "relative", True, "cross error"),
    "cross_gt_noise_rel": ("ground truth's own noise on it", "relative", True, "its GT noise"),
    "psnr_objects_db": ("PSNR over the objects", "dB", False, "PSNR objects"),
    "psnr_objects_db_direct_only": ("PSNR over the objects, direct light only", "dB", False, "PSNR objects, direct"),
    "psnr_db": ("PSNR, every pixel", "dB", False, "PSNR all pixels"),
}
# the fidelity floor's columns, in studies with floor = true (lftransfer.sim.floor, in the error's units)
FLOOR_METRICS = {
    "floor_transfer": ("the transfer's error, scored as the floors are", "relative", True, "transfer (scored)"),
    "floor": ("fidelity floor, both sides", "relative", True, "floor"),
    "real_floor": ("real side's floor", "relative", True, "real floor"),
    "synthetic_floor": ("synthetic side's floor", "relative", True, "synthetic floor"),
}
CELLS = "cells"


class StudyError(ValueError):
    """A study file that cannot be used, or a folder that cannot be resumed; the message names the file and field."""


class StudySetting(BaseModel):
    """One setting of a study: a name, changes to every scene's ``[render]`` and ``[rig]`` tables, and optionally a
    lens array redesigned at another pitch (module docstring)."""

    model_config = ConfigDict(extra="forbid")
    name: str = Field(min_length=1, max_length=40, pattern=r"^[A-Za-z0-9_.+-]+$")
    render: dict[str, object] = Field(default_factory=dict)
    rig: dict[str, object] = Field(default_factory=dict)
    array_pitch_mm: Optional[float] = Field(default=None, gt=0)

    @property
    def changes_rig(self) -> bool:
        return bool(self.rig) or self.array_pitch_mm is not None


def redesigned_array(rig, pitch_mm: float) -> dict:
    """``[rig]`` changes for a lens array of ``pitch_mm`` over the same extent as ``rig``'s: rows and columns
    scaled by the pitch ratio (at least 2 each), the focal length keeping the f-number (focal / pitch), the LF camera
    and projector keeping their pixels per lenslet (even sizes)."""
    k = rig.pitch_mm / pitch_mm

    def even(n: float) -> int:
        return max(2, 2 * int(round(n / 2)))

    return {"pitch_mm": float(pitch_mm), "focal_mm": float(rig.focal_mm * pitch_mm / rig.pitch_mm),
            "rows": max(2, int(round(rig.rows * k))), "cols": max(2, int(round(rig.cols * k))),
            "lf_camera": [even(rig.lf_camera[0] * k), even(rig.lf_camera[1] * k)],
            "projector": [even(rig.projector[0] * k), even(rig.projector[1] * k)]}


class StudyConfig(BaseModel):
    """A study file (module docstring)."""

    model_config = ConfigDict(extra="forbid")
    title: str = "study"
    scenes: list[str] = Field(min_length=1)
    truth_seeds: list[int] = Field(default_factory=lambda: [0], min_length=1)
    rig_model: choices.RigModel = choices.DEFAULT_RIG_MODEL
    bounces: int = Field(default=choices.DEFAULT_BOUNCES, ge=0, le=choices.MAX_BOUNCES)
    quick: bool = False
    gt_spp: Optional[int] = Field(default=None, ge=1)
    floor: bool = False
    setting: list[StudySetting] = Field(min_length=1)

    @field_validator("truth_seeds")
    @classmethod
    def _seeds(cls, v: list[int]) -> list[int]:
        if any(s < 0 for s in v) or len(set(v)) != len(v):
            raise ValueError(f"expected distinct integers >= 0, got {v}")
        return v

    @model_validator(mode="after")
    def _unique(self) -> "StudyConfig":
        names = [s.name for s in self.setting]
        if len(set(names)) != len(names):
            raise ValueError(f"setting names must differ, got {names}")
        if len(set(self.scenes)) != len(self.scenes):
            raise ValueError(f"scenes must differ, got {self.scenes}")
        return self


@dataclass(frozen=True)
class Study:
    """A validated study: its file, its configuration and its scenes (loaded, ``quick`` applied).

    Attributes:
        path: the study file.
        config: :class:`StudyConfig`.
        scenes: scene label (as the study file names it) -> ``SceneConfig``.
        digest: SHA-256 of the study file and the scene files (what a resumed study must match).
    """

    path: Path
    config: StudyConfig
    scenes: dict[str, object]
    digest: str

    def scene(self, label: str, setting: StudySetting | None = None):
        """The scene ``label``, with ``setting``'s changes to its ``[rig]`` (the redesigned array first) and
        ``[render]`` tables."""
        scene = self.scenes[label]
        if setting is None:
            return scene
        rig = {**(redesigned_array(scene.rig, setting.array_pitch_mm) if setting.array_pitch_mm else {}),
               **setting.rig}
        changes = {**({"rig": rig} if rig else {}), **({"render": setting.render} if setting.render else {})}
        return with_overrides(scene, **changes) if changes else scene

    def gt_spp(self, label: str) -> int:
        """Samples per pixel of the ground truth of scene ``label``: the study's ``gt_spp``, else the scene's."""
        from lftransfer.settings import Overrides, resolve_settings

        return resolve_settings(self.scenes[label], Overrides(gt_spp=self.config.gt_spp)).gt_spp


def builtin_studies() -> list[str]:
    """Names of the studies that come with lftransfer (``lft study NAME``)."""
    return sorted(p.stem for p in (Path(__file__).parent / "studies").glob("*.toml"))


def builtin_study(name: str) -> Path:
    """The file of the built-in study ``name``.

    Raises:
        StudyError: no such built-in study (the message lists them).
    """
    path = Path(__file__).parent / "studies" / f"{name}.toml"
    if not path.is_file():
        raise StudyError(f"{name!r} is not a built-in study ({', '.join(builtin_studies())})")
    return path


def load_study(path: str | Path) -> Study:
    """Read and validate a study file: its fields, its scenes (loaded) and each setting on each scene.

    Raises:
        StudyError: one line naming the file and the field (``study.scenes[1]``, ``setting[0].render``).
    """
    from lftransfer.scenes import quick_scene

    path = Path(path)
    data = read_toml(path, "study file", StudyError)
    if set(data) - {"study", "setting"}:
        raise StudyError(f"{path}: {sorted(set(data) - {'study', 'setting'})[0]}: unknown table (expected [study] "
                         f"and [[setting]])")
    tables = {**data.get("study", {}), "setting": data.get("setting", [])}
    try:
        config = StudyConfig.model_validate(tables)
    except ValidationError as exc:
        msg = validation_message(str(path), exc, root="<study>", model=StudyConfig, data=tables)
        raise StudyError(msg.replace(": scenes", ": study.scenes").replace(": truth_seeds", ": study.truth_seeds")
                         ) from None
    scenes, digest = {}, hashlib.sha256(path.read_bytes())
    for i, label in enumerate(config.scenes):
        file = Path(label) if label.endswith(".toml") else None
        if file is None and label not in builtin_scenes():
            raise StudyError(f"{path}: study.scenes[{i}]: {label!r} is neither a built-in scene "
                             f"({', '.join(builtin_scenes())}) nor a .toml file")
        file = builtin_scene(label) if file is None else (file if file.is_absolute() else path.parent / file)
        if not file.is_file():
            raise StudyError(f"{path}: study.scenes[{i}]: {file}: no such file")
        try:
            scene = load_scene(file)
        except SceneError as exc:
            raise StudyError(f"{path}: study.scenes[{i}]: {exc}") from None
        scenes[label] = quick_scene(scene) if config.quick else scene
        digest.update(file.read_bytes())
    keys = [cell_key(label, 0, "") for label in config.scenes]
    if len(set(keys)) != len(keys):
        raise StudyError(f"{path}: study.scenes: two scenes have the same name ({config.scenes}); their cells' files "
                         f"would collide, rename one")
    study = Study(path=path, config=config, scenes=scenes, digest=digest.hexdigest())
    for j, setting in enumerate(config.setting):
        for label in config.scenes:
            try:
                study.scene(label, setting)
            except SceneError as exc:
                raise StudyError(f"{path}: setting[{j}] ({setting.name}) on {label}: {exc}") from None
    return study


@dataclass(frozen=True)
class StudyCell:
    """One cell: a scene on the simulated rig of one hidden truth, with one setting, against its ground truth.

    Attributes:
        scene: the scene's label in the study file.
        seed: the hidden truth's seed.
        setting: the setting's name.
        metrics: :data:`METRICS` key -> value (None where the scene leaves it undefined).
        seconds: wall time of the transfer, s (the ground truth and calibration are not in it).
    """

    scene: str
    seed: int
    setting: str
    metrics: dict[str, float | None]
    seconds: float

    @property
    def key(self) -> str:
        """The cell's file name, without ``.json``."""
        return cell_key(self.scene, self.seed, self.setting)


def cell_key(scene: str, seed: int, setting: str) -> str:
    """A file name for a cell: the scene's name (a file's stem, made safe), the seed and the setting."""
    name = Path(scene).stem if scene.endswith(".toml") else scene
    safe = "".join(c if c.isalnum() or c in "-_." else "_" for c in name)
    return f"{safe}-seed{seed}-{setting}"


@dataclass
class StudyResult:
    """A finished (or partly finished) study.

    Attributes:
        title: the study's title.
        scenes, seeds, settings: the axes, in the study file's order.
        cells: every finished cell.
        rig_model: what the pipeline knew of each rig.
        bounces: N.
        cluster: where it ran (None: in one process).
        seconds: wall time of the whole study, s (every run of a resumed one, added up).
        floor: whether the cells carry the fidelity floor (:data:`FLOOR_METRICS`).
        pitches: setting -> its redesigned array's pitch, mm (settings with ``array_pitch_mm``).
    """

    title: str
    scenes: list[str]
    seeds: list[int]
    settings: list[str]
    rig_model: str
    bounces: int
    cells: list[StudyCell] = field(default_factory=list)
    cluster: dict | None = None
    seconds: float = 0.0
    floor: bool = False
    pitches: dict[str, float] = field(default_factory=dict)

    @property
    def metrics(self) -> dict:
        """The cells' columns: :data:`METRICS`, and :data:`FLOOR_METRICS` where the cells carry floors."""
        return {**METRICS, **(FLOOR_METRICS if self.floor else {})}

    def cell(self, scene: str, seed: int, setting: str) -> StudyCell | None:
        return next((c for c in self.cells if (c.scene, c.seed, c.setting) == (scene, seed, setting)), None)

    def summary(self, metric: str) -> list[dict]:
        """Per scene and setting: the metric's mean over the seeds (None where a seed lacks it), and its range.

        Returns:
            Rows ``{"scene", "setting", "mean", "min", "max", "n"}`` in the study's order.
        """
        rows = []
        for scene in self.scenes:
            for setting in self.settings:
                values = [c.metrics.get(metric) for c in self.cells if (c.scene, c.setting) == (scene, setting)]
                finite = [v for v in values if v is not None and math.isfinite(v)]
                rows.append({"scene": scene, "setting": setting, "n": len(finite),
                             "mean": float(np.mean(finite)) if finite else None,
                             "min": float(min(finite)) if finite else None,
                             "max": float(max(finite)) if finite else None})
        return rows

    def to_json(self) -> dict:
        return {**{k: v for k, v in asdict(self).items() if k != "cells"},
                "cells": [asdict(c) for c in self.cells],
                "summary": {m: self.summary(m) for m in self.metrics}}

    def markdown(self) -> str:
        """The table: one row per scene and setting, the mean over the seeds of each metric (range in brackets
        where there are several seeds)."""
        metrics = self.metrics
        head = "| scene | setting | " + " | ".join(f"{metrics[m][3]} ({metrics[m][1]})" for m in metrics) + " |"
        rows = [head, "|" + "---|" * (len(metrics) + 2)]
        tables = {m: {(r["scene"], r["setting"]): r for r in self.summary(m)} for m in metrics}
        for scene in self.scenes:
            for setting in self.settings:
                cells = []
                for m in metrics:
                    r = tables[m][(scene, setting)]
                    fmt = "{:.2f}" if metrics[m][1] == "dB" else "{:.3f}"
                    if r["mean"] is None:
                        cells.append("n/a")
                    elif r["n"] > 1:
                        cells.append(f"{fmt.format(r['mean'])} ({fmt.format(r['min'])}..{fmt.format(r['max'])})")
                    else:
                        cells.append(fmt.format(r["mean"]))
                rows.append(f"| {scene} | {setting} | " + " | ".join(cells) + " |")
        return "\n".join(rows) + "\n"


class StudyWorker(Worker):
    """A worker of a study: keeps each (scene, seed) rig it has opened; every method is one task of a round.

    Args:
        study: :class:`Study`.
        threads: Dr.Jit threads (:class:`lftransfer.runs.cluster.Worker`).
    """

    def __init__(self, study: Study, threads: int | None = None) -> None:
        super().__init__(threads)
        self.study = study
        self._rigs: dict[tuple[str, int], object] = {}

    def _opened(self, label: str, seed: int):
        from lftransfer.runs.pipeline import RunOptions
        from lftransfer.runs.rigs import open_rig

        if (label, seed) not in self._rigs:
            self._rigs[(label, seed)] = open_rig(self.study.scene(label), RunOptions(truth_seed=seed))
        return self._rigs[(label, seed)]

    def prepare(self, label: str, seed: int, use_cache: bool):
        """Round 1 of a (scene, seed) pair: its rig model and synthetic scene, and its ground truth rendered into
        the cache. Returns (model, pipeline scene), or (None, None) where every setting changes the rig."""
        from lftransfer.runs.rigs import knowledge

        opened = self._opened(label, seed)
        opened.oracle.ground_truth(spp=self.study.gt_spp(label), use_cache=use_cache)
        if all(s.changes_rig for s in self.study.config.setting):
            return None, None              # every cell knows its own rig (no calibration of one it never uses)
        known = knowledge(opened, self.study.scene(label), self.study.config.rig_model)
        return known.model, known.scene

    def cell(self, label: str, seed: int, setting_name: str, model, ps, use_cache: bool) -> StudyCell:
        """Round 2: one cell (its ground truth read from the cache, or rendered again where it is not shared). A
        setting that changes the rig gets a simulated rig of its own and its own rig model (the same hidden world,
        so the same ground truth)."""
        from lftransfer.runs.pipeline import RunOptions
        from lftransfer.runs.rigs import knowledge, open_rig
        from lftransfer.settings import Overrides, resolve_settings
        from lftransfer.sim.metrics import evaluate
        from lftransfer.transfer.bounce import run_transfer

        setting = next(s for s in self.study.config.setting if s.name == setting_name)
        scene = self.study.scene(label, setting)
        if setting.changes_rig:
            opened = open_rig(scene, RunOptions(truth_seed=seed))
            known = knowledge(opened, scene, self.study.config.rig_model)
            model, ps = known.model, known.scene
        else:
            opened = self._opened(label, seed)
            ps = with_overrides(ps, render=setting.render) if setting.render else ps
        settings = resolve_settings(scene, Overrides(bounces=self.study.config.bounces)).transfer
        t0 = time.perf_counter()
        opened.start_frame(0)
        result = run_transfer(opened.rig, model, ps, settings)
        seconds = time.perf_counter() - t0
        gt = opened.oracle.ground_truth(spp=self.study.gt_spp(label), use_cache=use_cache)
        metrics = evaluate(result, gt)
        values = {m: getattr(metrics, m) for m in METRICS}
        if self.study.config.floor:
            floor = opened.oracle.fidelity_floor(opened.rig, result, gt, settings)
            values.update(floor_transfer=floor.transfer, floor=floor.floor, real_floor=floor.real_floor,
                          synthetic_floor=floor.synthetic_floor)
        return StudyCell(scene=label, seed=int(seed), setting=setting_name, metrics=values, seconds=seconds)


def _resumed(study: Study, out: Path, resume: bool, result: StudyResult) -> float:
    """With ``resume`` on a folder of the same study, its finished cells into ``result`` and the seconds its earlier
    runs took; else 0, with an earlier study's cells and outputs removed from ``out``.

    Raises:
        StudyError: ``resume`` on a folder of another study.
    """
    cells_dir, marker = out / CELLS, out / "study_key.json"
    before = 0.0                                   # seconds the earlier runs of a resumed study took
    if resume and marker.is_file():
        key = read_json(marker, "study key", StudyError)
        before = float(key.get("seconds", 0.0))
        if key.get("digest") != study.digest:
            raise StudyError(f"--resume: {out} holds another study (or the study or its scenes changed); run "
                             f"without --resume to start again")
        for path in sorted(cells_dir.glob("*.json")):
            data = read_json(path, "study cell", StudyError)
            result.cells.append(StudyCell(**data))
    else:
        if cells_dir.is_dir():
            for path in cells_dir.glob("*.json"):
                path.unlink()
        for name in ("study.json", "study.md", "study.png", "study.html"):
            (out / name).unlink(missing_ok=True)
    return before


def run_study(study: Study, out: str | Path, *, cluster: ClusterSpec | None = None, resume: bool = False,
              use_cache: bool = True, progress: Callable[[str, int, int], None] | None = None) -> StudyResult:
    """Run every cell of a study (module docstring) and write the outputs into ``out``.

    Args:
        study: from :func:`load_study`.
        out: output folder (made).
        cluster: where to run (None: in this process).
        resume: keep the cells a previous run of the same study wrote into ``out``.
        use_cache: read and write the ground-truth cache.
        progress: called with a message, the cells done and the total after each cell.

    Returns:
        :class:`StudyResult` (also ``study.json``).

    Raises:
        StudyError: ``resume`` on a folder of another study.
    """
    out = Path(out)
    c = study.config
    pairs = [(label, seed) for label in c.scenes for seed in c.truth_seeds]
    total = len(pairs) * len(c.setting)
    result = StudyResult(title=c.title, scenes=list(c.scenes), seeds=list(c.truth_seeds),
                         settings=[s.name for s in c.setting], rig_model=c.rig_model, bounces=c.bounces,
                         floor=c.floor, pitches={s.name: s.array_pitch_mm for s in c.setting if s.array_pitch_mm})
    cells_dir = out / CELLS
    marker = out / "study_key.json"
    before = _resumed(study, out, resume, result)
    cells_dir.mkdir(parents=True, exist_ok=True)
    def mark() -> None:
        write_json(marker, {"digest": study.digest, "study": str(study.path),
                            "seconds": before + time.perf_counter() - t0})

    t0 = time.perf_counter()
    mark()
    finished = {c_.key for c_ in result.cells}
    todo = [(label, seed, s.name) for label, seed in pairs for s in c.setting
            if cell_key(label, seed, s.name) not in finished]
    need = sorted({(label, seed) for label, seed, _ in todo}, key=pairs.index)
    say = progress or (lambda msg, done, n: None)
    write_status(out, "running", rig="sim")
    with tracked_run(out, "sim", interrupted="interrupted (Ctrl-C); --resume continues"):

        def keep(cell: StudyCell) -> None:
            write_json(cells_dir / f"{cell.key}.json", asdict(cell))
            mark()
            result.cells.append(cell)
            say(f"{cell.scene}, seed {cell.seed}, {cell.setting}", len(result.cells), total)

        def rounds(pool) -> None:
            """Round 1 (each scene and seed's rig model and ground truth), then every cell, on ``pool``."""
            prepared = {}
            for (label, seed, _), prep in pool.map("prepare", [(label, seed, use_cache) for label, seed in need]):
                prepared[(label, seed)] = prep
                say(f"{label}, seed {seed}: rig model and ground truth", len(result.cells), total)
            items = [(label, seed, name, *prepared[(label, seed)], use_cache) for label, seed, name in todo]
            for _, cell in pool.map("cell", items):
                keep(cell)

        if cluster is None:
            rounds(LocalPool(_LocalStudyWorker(study)))
        else:
            from lftransfer.runs.cluster import WorkerPool, connect

            with connect(cluster) as info:
                pool = WorkerPool(StudyWorker, (study,), info, cluster.workers)
                rounds(pool)
                result.cluster = pool.describe()
        order = {(label, seed, s): i for i, (label, seed, s) in
                 enumerate((label, seed, s.name) for label, seed in pairs for s in c.setting)}
        result.cells.sort(key=lambda x: order[(x.scene, x.seed, x.setting)])
        result.seconds = before + time.perf_counter() - t0
        mark()
        write_study_outputs(out, result)
    return result


class _LocalStudyWorker(StudyWorker):
    """A :class:`StudyWorker` in this process (no cluster)."""

    def __init__(self, study: Study) -> None:
        self.study = study
        self._rigs = {}


def write_study_outputs(out: Path, result: StudyResult) -> None:
    """``study.json``, ``study.md``, ``study.png`` (the cross-transfer error and the PSNR over the objects per scene,
    a bar per setting) and ``study.html`` (:mod:`lftransfer.reports.study_report`)."""
    from lftransfer.reports.study_report import write_study_report

    write_json(out / "study.json", result.to_json())
    write_text(out / "study.md", f"# {result.title}\n\n" + result.markdown())
    write_study_report(out, result)

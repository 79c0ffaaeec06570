"""``lft study``: scenes x hidden truths x settings -> one table."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer
from rich.console import Console
from rich.markup import escape

from lftransfer.app.cli.common import check_before_work, cluster_spec, command, ending_cleanly, progress_bar
from lftransfer.app.cli.options import Cluster, MaxMemory, NoCache, OutDir, Workers, flag
from lftransfer.app.terminal import fail

__all__ = ["register"]


def register(app: typer.Typer) -> None:
    """Add ``study`` to ``app``."""

    @command(app, "study")
    def study_cmd(study_file: Annotated[Path, typer.Argument(metavar="STUDY.toml", help=escape(
                      "Study file: [study] (scenes, truth_seeds, rig_model, bounces, quick, gt_spp, floor) and "
                      "[[setting]] tables (name, render = {...}, rig = {...}, array_pitch_mm); or a built-in "
                      "study's name (pitch: the rig designer); see docs/architecture.md, 'Scale-out'."))],
                  out: OutDir = Path("out/study"),
                  resume: Annotated[bool, flag("--resume", "Keep the cells a previous run of the same study wrote "
                                                           "into DIR.")] = False,
                  no_cache: NoCache = False, cluster: Cluster = None, workers: Workers = None,
                  max_memory: MaxMemory = None) -> None:
        """Scenes x hidden truths x settings -> one table: each cell a converged transfer on the simulated rig,
        measured against its ground truth (study.json, study.md, study.png, study.html)."""
        from lftransfer.runs.cluster import ClusterError
        from lftransfer.runs.study import StudyError, load_study, run_study

        from lftransfer.runs.study import builtin_study, builtin_studies

        spec = cluster_spec(cluster, workers)
        if not study_file.is_file() and str(study_file) in builtin_studies():
            study_file = builtin_study(str(study_file))
        if not study_file.is_file():
            fail(f"{study_file}: no such file (built-in studies: {', '.join(builtin_studies())})")
        try:
            study = load_study(study_file)
        except StudyError as exc:
            fail(str(exc))
        c = study.config
        for scene in study.scenes.values():
            check_before_work(scene, out_dir=out, cache=not no_cache, max_memory=max_memory, bounces=c.bounces,
                              calibrate=c.rig_model == "calibrated")
        total = len(c.scenes) * len(c.truth_seeds) * len(c.setting)
        with progress_bar(50) as bar:
            task = bar.add_task("set-up", total=total)
            with ending_cleanly(bar, interrupted=f"interrupted; the finished cells are in {out / 'cells'}; --resume "
                                                 "continues", refused=(StudyError,), failed=(ClusterError,),
                                where=f"the finished cells are in {out / 'cells'}; --resume continues"):
                result = run_study(study, out, cluster=spec, resume=resume, use_cache=not no_cache,
                                   progress=lambda msg, done, n: bar.update(task, completed=done,
                                                                            description=escape(msg[:50])))
        Console().print(escape(f"# {result.title}"))
        Console().print(escape(result.markdown()), soft_wrap=True)
        pitch = ", pitch.png" if (out / "pitch.png").is_file() else ""
        Console().print(escape(f"wrote {out / 'study.html'}, study.json, study.md, study.png{pitch} "
                               f"({result.seconds:.0f} s"
                               + (f" on {result.cluster['workers']} workers" if result.cluster else "") + ")"),
                        soft_wrap=True)

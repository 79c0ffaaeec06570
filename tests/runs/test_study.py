"""``lft study``: scenes x hidden truths x settings -> one table, written cell by cell, resumable, and the same on a
cluster."""

from __future__ import annotations

import json

import pytest

from lftransfer.runs.study import METRICS, StudyError, load_study, run_study
from tests.small import write_tiny_scene

STUDY = """
[study]
title = "box against linear"
scenes = ["tiny.toml"]
truth_seeds = [1, 2]
rig_model = "oracle"
bounces = 1

[[setting]]
name = "box"
render = {{ reconstruction = "box" }}

[[setting]]
name = "point"
render = {{ lighting_model = "point" }}
{extra}
"""


def _study(tmp_path, extra: str = "", **scene):
    write_tiny_scene(tmp_path / "tiny.toml", **scene)
    path = tmp_path / "study.toml"
    path.write_text(STUDY.format(extra=extra), encoding="utf-8")
    return path


def test_01_bad_study_files_name_the_field(tmp_path):
    path = _study(tmp_path)
    cases = [
        (STUDY.format(extra="").replace("truth_seeds = [1, 2]", "truth_seeds = [1, 1]"), "study.truth_seeds"),
        (STUDY.format(extra="").replace('"tiny.toml"', '"missing.toml"'), "study.scenes[0]: "),
        (STUDY.format(extra="").replace('"tiny.toml"', '"fig9"'), "neither a built-in scene"),
        (STUDY.format(extra="").replace('name = "point"', 'name = "box"'), "setting names must differ"),
        (STUDY.format(extra="").replace('lighting_model = "point"', 'lighting_model = "magic"'),
         "setting[1] (point) on tiny.toml"),
        (STUDY.format(extra="[other]\nx = 1"), "other: unknown table"),
        (STUDY.format(extra="").replace("bounces = 1", "bounces = -1"), "bounces"),
    ]
    for text, words in cases:
        path.write_text(text, encoding="utf-8")
        with pytest.raises(StudyError, match=None) as err:
            load_study(path)
        assert str(path) in str(err.value) and words in str(err.value), str(err.value)


def test_02_every_cell_measured_written_and_resumed(variant, tmp_path):
    """2 seeds x 2 settings on a tiny scene: every cell measured against its ground truth, the table, the plot and
    the page written; a resumed study keeps the finished cells and renders only the missing one. Each setting
    reaches its cells (the two lighting models give different numbers on every seed), and so does each seed."""
    study = load_study(_study(tmp_path))
    out = tmp_path / "out"
    seen = []
    result = run_study(study, out, progress=lambda msg, done, n: seen.append((done, n)))
    assert seen[-1] == (4, 4) and len(result.cells) == 4
    assert [(c.seed, c.setting) for c in result.cells] == [(1, "box"), (1, "point"), (2, "box"), (2, "point")]
    for c in result.cells:
        assert set(c.metrics) == set(METRICS)
        assert 0 < c.metrics["cross_transfer_rel_error"] < 1.5 and c.metrics["psnr_objects_db"] > 10
    for seed in (1, 2):
        box, point = result.cell("tiny.toml", seed, "box"), result.cell("tiny.toml", seed, "point")
        assert point.metrics["cross_transfer_rel_error"] != box.metrics["cross_transfer_rel_error"]
        assert point.metrics["psnr_objects_db"] != box.metrics["psnr_objects_db"]
    assert result.cells[0].metrics != result.cells[2].metrics
    data = json.loads((out / "study.json").read_text())
    assert len(data["cells"]) == 4 and data["summary"]["psnr_db"][0]["n"] == 2
    table = (out / "study.md").read_text()
    assert "| tiny.toml | box |" in table and "| tiny.toml | point |" in table
    page = (out / "study.html").read_text()
    assert "box against linear" in page and "data:image/svg+xml;base64," in page and "<script" not in page
    assert (out / "study.png").read_bytes()[:4] == b"\x89PNG"
    assert json.loads((out / "status.json").read_text())["state"] == "complete"

    (out / "cells" / "tiny-seed2-point.json").unlink()
    seen.clear()
    again = run_study(study, out, resume=True, progress=lambda msg, done, n: seen.append(msg))
    assert seen == ["tiny.toml, seed 2: rig model and ground truth", "tiny.toml, seed 2, point"]
    assert [c.metrics for c in again.cells] == [c.metrics for c in result.cells]     # the same numbers again

    other = load_study(_study(tmp_path, light=(0.28, 0.12, 0.0)))                   # the scene changed
    with pytest.raises(StudyError, match="holds another study"):
        run_study(other, out, resume=True)


@pytest.mark.slow
@pytest.mark.ray
def test_03_study_on_a_cluster_equals_one_process(variant, tmp_path):
    pytest.importorskip("ray")
    from lftransfer.runs.cluster import ClusterSpec

    study = load_study(_study(tmp_path))
    one = run_study(study, tmp_path / "one", use_cache=False)
    many = run_study(study, tmp_path / "many", use_cache=False, cluster=ClusterSpec("local", workers=2))
    assert many.cluster["workers"] == 2
    assert [c.metrics for c in many.cells] == [c.metrics for c in one.cells]


def test_04_the_command(variant, tmp_path):
    """``lft study``: the table on the terminal and the files; a bad study file is one line naming the field."""
    from typer.testing import CliRunner

    from lftransfer.app.cli import app

    runner = CliRunner()
    path = _study(tmp_path)
    path.write_text(STUDY.format(extra="").replace("truth_seeds = [1, 2]", "truth_seeds = [1]"), encoding="utf-8")
    result = runner.invoke(app, ["study", str(path), "--out", str(tmp_path / "out")])
    assert result.exit_code == 0, result.output
    assert "| tiny.toml | box |" in result.output and (tmp_path / "out" / "study.html").is_file()
    path.write_text(STUDY.format(extra="").replace("bounces = 1", "bounces = 99"), encoding="utf-8")
    bad = runner.invoke(app, ["study", str(path), "--out", str(tmp_path / "bad")])
    text = " ".join(bad.output.split())
    assert bad.exit_code == 2 and "study.toml" in text and "bounces" in text, text
    missing = runner.invoke(app, ["study", str(tmp_path / "none.toml")])
    assert missing.exit_code == 2 and "no such file" in " ".join(missing.output.split())


def test_05_the_rig_designer_redesigns_the_array_and_finds_the_floors(variant, tmp_path):
    """Settings with array_pitch_mm: the array keeps its extent and f-number, the devices their pixels per
    lenslet; each cell is transferred on its own rig and carries the fidelity floor (the real side's never above
    the transfer's own, scored alike); the pitch plot is written; the built-in pitch study loads."""
    from lftransfer.runs.study import FLOOR_METRICS, builtin_studies, builtin_study, redesigned_array
    from lftransfer.scenes import load_scene

    write_tiny_scene(tmp_path / "tiny.toml")
    rig = load_scene(tmp_path / "tiny.toml").rig
    half = redesigned_array(rig, rig.pitch_mm / 2)
    assert (half["rows"], half["cols"]) == (2 * rig.rows, 2 * rig.cols)
    assert half["focal_mm"] / half["pitch_mm"] == pytest.approx(rig.focal_mm / rig.pitch_mm)
    assert half["lf_camera"] == [2 * rig.lf_camera[0], 2 * rig.lf_camera[1]]
    path = tmp_path / "pitch.toml"
    path.write_text("""
[study]
title = "pitch"
scenes = ["tiny.toml"]
truth_seeds = [1]
rig_model = "oracle"
bounces = 1
floor = true

[[setting]]
name = "coarse"
array_pitch_mm = 25.4

[[setting]]
name = "fine"
array_pitch_mm = 19.05
""", encoding="utf-8")
    study = load_study(path)
    assert study.scene("tiny.toml", study.config.setting[1]).rig.rows == 4
    out = tmp_path / "out"
    result = run_study(study, out)
    assert result.pitches == {"coarse": 25.4, "fine": 19.05}
    for c in result.cells:
        assert set(c.metrics) == set(METRICS) | set(FLOOR_METRICS)
        assert c.metrics["real_floor"] is not None and c.metrics["floor"] > 0
    assert result.cells[0].metrics["cross_transfer_rel_error"] != result.cells[1].metrics["cross_transfer_rel_error"]
    assert (out / "pitch.png").read_bytes()[:4] == b"\x89PNG"
    assert "floor" in (out / "study.md").read_text()
    assert "pitch" in builtin_studies() and load_study(builtin_study("pitch")).config.floor


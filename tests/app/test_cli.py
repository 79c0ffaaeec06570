"""The ``lft`` command: bad input gets a clear error, not a traceback."""

from __future__ import annotations

from typer.testing import CliRunner

from lftransfer.app.cli import app

runner = CliRunner()


def _text(result) -> str:
    return " ".join((result.output or "").split())


def test_01_missing_scene_file(tmp_path):
    result = runner.invoke(app, ["run", str(tmp_path / "nope.toml"), "--out", str(tmp_path / "out")])
    assert result.exit_code == 2
    assert "nope.toml" in _text(result) and "no such file" in _text(result)
    assert result.exception is None or isinstance(result.exception, SystemExit)


def test_02_invalid_scene_names_file_and_field(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text('[light]\nposition = [0, 0.2, 0]\nintensity = [1, 1, 1]\n'
                   '[[real]]\nname = "b"\nshape = "box"\nsize = [0.1, 0.1]\ntranslate = [0, 0, 0.2]\n')
    result = runner.invoke(app, ["run", str(bad), "--out", str(tmp_path / "out")])
    assert result.exit_code == 2
    text = " ".join(_text(result).split())
    assert "bad.toml" in text and "real[0].size" in text
    assert not (tmp_path / "out").exists()


def test_03_unknown_lighting_model(tmp_path):
    from lftransfer.scenes import builtin_scene

    result = runner.invoke(app, ["run", str(builtin_scene("fig4")), "--lighting-model", "magic",
                                 "--out", str(tmp_path / "out")])
    assert result.exit_code == 2 and "--lighting-model" in _text(result)


def test_04_help_lists_commands():
    result = runner.invoke(app, ["--help"])
    assert result.exit_code == 0 and "demo" in result.output and "run" in result.output


def test_05_rig_spec_errors(tmp_path):
    from lftransfer.scenes import builtin_scene

    for spec, words in (("gpu", "expected 'sim'"), (f"hardware:{tmp_path / 'none.toml'}", "does not exist"),
                        (f"replay:{tmp_path}", "not a recording")):
        result = runner.invoke(app, ["run", str(builtin_scene("fig4")), "--rig", spec, "--out", str(tmp_path / "o")])
        assert result.exit_code == 2 and words in _text(result), _text(result)
    result = runner.invoke(app, ["run", str(builtin_scene("fig4")), "--rig", f"replay:{tmp_path}",
                                 "--rig-model", "oracle", "--out", str(tmp_path / "o")])
    assert result.exit_code == 2


def test_builtin_scene_by_name():
    """A built-in scene's name stands for its file; an unknown name lists the built-in scenes."""
    from pathlib import Path

    from lftransfer.app.cli.common import load

    assert load(Path("fig6"), quick=True).effect.on == "bowl"
    from lftransfer.scenes import builtin_scenes

    result = runner.invoke(app, ["render", "fig7", "--quick"])
    names = ", ".join(builtin_scenes())
    assert "occlusion" in names and "fig4" in names
    assert result.exit_code != 0 and f"fig7: no such file (built-in scenes: {names})" in _text(result)


def test_06_cluster_option_errors(tmp_path):
    """--cluster is checked before any work: its form, --workers without it, and the live loop (sequential)."""
    for args, words in ((["--mode", "converged", "--cluster", "slurm"], "expected 'auto', 'local' or 'ray://HOST:PORT'"),
                        (["--mode", "converged", "--workers", "2"], "--workers: needs --cluster"),
                        (["--cluster", "local"], "needs --mode converged: the live loop is sequential")):
        result = runner.invoke(app, ["render", "fig4", "--quick", "--out", str(tmp_path / "o"), *args])
        assert result.exit_code == 2 and words in _text(result), _text(result)
        assert not (tmp_path / "o").exists()


def test_07_docs_cli_md_is_what_the_commands_say(tmp_path):
    """docs/cli.md is generated from the commands (``make cli-docs``): regenerated here it is the same file, with
    no HTML entities left in its Markdown, so the docs cannot drift from the options (run ``make cli-docs``
    after changing an option or a setting's help)."""
    import html
    import subprocess
    import sys
    from pathlib import Path

    out = tmp_path / "cli.md"
    typer_exe = Path(sys.executable).parent / "typer"
    subprocess.run([str(typer_exe), "lftransfer.app.cli", "utils", "docs", "--name", "lft", "--output", str(out)],
                   check=True, capture_output=True)
    generated = html.unescape(out.read_text(encoding="utf-8"))
    stored = (Path(__file__).resolve().parents[2] / "docs" / "cli.md").read_text(encoding="utf-8")
    assert "&#x27;" not in stored and "&lt;" not in stored
    assert generated == stored, "docs/cli.md is out of date: run make cli-docs"


def test_08_every_command_says_something_within_two_seconds(tmp_path):
    """Off a terminal (stderr a pipe), ``lft calibrate`` prints its first line within 2 s of starting, before it
    loads the scene or the renderer; then each step of its progress is a line of its own (a log shows where a run
    is)."""
    import subprocess
    import sys
    import time
    from pathlib import Path

    exe = Path(sys.executable).parent / "lft"
    start = time.monotonic()
    proc = subprocess.Popen([str(exe), "calibrate", "fig4", "--quick", "--out", str(tmp_path / "cal.json")],
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    try:
        first = proc.stderr.readline()
        took = time.monotonic() - start
        assert first.strip() == "lft calibrate rig: starting", first
        assert took < 2.0, f"the first line came after {took:.2f} s"
        second = proc.stderr.readline()
        assert second.split(" ", 1)[0].count("/") == 1 and second.split(" ", 1)[0].split("/")[0].isdigit(), second
    finally:
        proc.kill()
        proc.wait()


def test_09_the_simulated_rig_photographs_what_the_lenslet_step_reads(variant, tmp_path):
    """``lft sim capture --kind spots --truth`` writes the LF camera's codes as a 16-bit PNG and the true lenslet
    centres; ``lft calibrate lenslets`` finds every centre from the PNG within 0.05 px of the truth (measured
    0.004 px RMS at --quick); the truth of another hidden rig (negative control) is over a pixel away."""
    import numpy as np

    for seed, folder in ((0, tmp_path / "a"), (3, tmp_path / "b")):
        result = runner.invoke(app, ["sim", "capture", "fig4", "--quick", "--kind", "spots", "--truth", "--out",
                                     str(folder), "--truth-seed", str(seed)])
        assert result.exit_code == 0, (result.output, result.exception)
    assert (tmp_path / "a" / "lf_spots.png").stat().st_size > 0
    result = runner.invoke(app, ["calibrate", "lenslets", str(tmp_path / "a" / "lf_spots.png"), "--lattice", "hex",
                                 "--out", str(tmp_path / "centres.csv")])
    assert result.exit_code == 0, (result.output, result.exception)
    found = np.loadtxt(tmp_path / "centres.csv", delimiter=",", skiprows=1)
    truth = np.loadtxt(tmp_path / "a" / "truth_centres.csv", delimiter=",", skiprows=1)
    other = np.loadtxt(tmp_path / "b" / "truth_centres.csv", delimiter=",", skiprows=1)
    assert found.shape == truth.shape == (120, 2)
    assert np.abs(found - truth).max() < 0.05
    assert np.linalg.norm(found - other, axis=1).mean() > 1.0
    bad = runner.invoke(app, ["sim", "capture", "fig4", "--quick", "--kind", "flat", "--out", str(tmp_path / "c")])
    assert bad.exit_code == 2 and "--kind: expected one of spots, white, scene" in " ".join(bad.output.split())


def test_10_a_new_scene_to_start_from(tmp_path):
    """``lft new scene PATH`` writes a commented scene with two real and two synthetic objects that loads as it is;
    it does not write over a file without --force, and a name that is not .toml is refused."""
    from lftransfer.scenes import load_scene

    path = tmp_path / "mine.toml"
    result = runner.invoke(app, ["new", "scene", str(path)])
    assert result.exit_code == 0, (result.output, result.exception)
    scene = load_scene(path)
    assert len(scene.real) == 2 and len(scene.synthetic) == 2 and scene.lights
    assert path.read_text().count("#") > 20 and "docs/scene-format.md" in path.read_text()
    again = runner.invoke(app, ["new", "scene", str(path)])
    assert again.exit_code == 2 and "--force" in " ".join(again.stderr.split())
    assert runner.invoke(app, ["new", "scene", str(path), "--force"]).exit_code == 0
    assert runner.invoke(app, ["new", "scene", str(tmp_path / "mine.txt")]).exit_code == 2

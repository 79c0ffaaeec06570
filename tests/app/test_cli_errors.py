"""Every error of the ``lft`` command is one line on stderr, exit code 2 for bad input, checked before the work
starts; no traceback unless ``--debug``. These tests stop any command that gets past its checks (``_run`` and
the rig are replaced), so they take well under a second each."""

from __future__ import annotations

import json
import re

import cv2
import numpy as np
import pytest
from typer.testing import CliRunner

from lftransfer.app.cli import app
from tests.small import nominal_calibration, tiny_scene_text, write_tiny_scene
from tests.runs.test_paths import read_only_dir  # noqa: F401  (fixture)

runner = CliRunner()


class WorkStarted(Exception):
    """Raised by the stand-ins below: the command got past its checks."""


@pytest.fixture
def no_work(monkeypatch):
    """Replace the run and the rig: reaching them means the checks let the command through."""
    def started(*args, **kwargs):
        raise WorkStarted()

    monkeypatch.setattr("lftransfer.app.cli.run._run", started)
    monkeypatch.setattr("lftransfer.runs.pipeline.open_rig", started)
    monkeypatch.setattr("lftransfer.runs.rigs.open_rig", started)
    monkeypatch.setattr("lftransfer.runs.sequence.open_rig", started)


@pytest.fixture
def scene(tmp_path):
    return write_tiny_scene(tmp_path / "tiny.toml")


def _invoke(args, **kw):
    return runner.invoke(app, [str(a) for a in args], **kw)


STARTING = re.compile(r"^lft [a-z -]+: starting$")
STEP = re.compile(r"^\d+/\d+ \S")                # a progress bar's step, as a line off a terminal


def _one_line_error(result, code: int = 2, progress: bool = False) -> str:
    """The command ended with ``code`` and exactly one line on stderr, ``error: ...``, without a traceback (after
    the command's first line, ``lft COMMAND: starting``; with ``progress``: after the progress bar's steps and its
    last line; ``warning: ...`` lines before it, e.g. a calibration file without its light section, are the run's
    own and not counted)."""
    assert result.exit_code == code, (result.exit_code, result.output, result.exception)
    assert not isinstance(result.exception, WorkStarted), "the work started before the check"
    lines = [line for line in result.stderr.splitlines() if line.strip() and not line.startswith("warning: ")
             and not STARTING.match(line)]
    if progress:
        lines = [line for line in lines if not STEP.match(line)]
        assert len(lines) == 2 and re.search(r"\d+/\d+ \d+:\d\d:\d\d$", lines[0]), result.stderr
        lines = lines[1:]
    assert len(lines) == 1 and lines[0].startswith("error: "), result.stderr
    assert "Traceback" not in result.output
    return lines[0]


# ---- item 2: output paths checked up front ------------------------------------------------------------------

def test_01_out_that_is_a_file(scene, tmp_path, no_work):
    target = tmp_path / "taken"
    target.write_text("x")
    line = _one_line_error(_invoke(["run", scene, "--out", target, "--rig-model", "nominal"]))
    assert f"--out {target}: is a file, expected a folder" in line


def test_02_read_only_output_folder(scene, read_only_dir, no_work):  # noqa: F811
    line = _one_line_error(_invoke(["run", scene, "--out", read_only_dir / "run", "--rig-model", "nominal"]))
    assert "cannot write there" in line and str(read_only_dir) in line


def test_03_calibrate_out_naming_a_folder(scene, tmp_path, no_work):
    line = _one_line_error(_invoke(["calibrate", scene, "--out", tmp_path]))
    assert f"--out {tmp_path}: is a folder, expected a file name (e.g. --out {tmp_path / 'calibration.json'})" in line
    line = _one_line_error(_invoke(["bench", "--scene", scene, "--json", tmp_path]))
    assert "--json" in line and "is a folder" in line


def test_04_unwritable_cache_folder(scene, tmp_path, monkeypatch, no_work):
    blocker = tmp_path / "cache-file"
    blocker.write_text("x")
    monkeypatch.setenv("LFT_CACHE_DIR", str(blocker))
    line = _one_line_error(_invoke(["run", scene, "--out", tmp_path / "out", "--rig-model", "nominal"]))
    assert "ground-truth cache" in line and "LFT_CACHE_DIR" in line and "--no-cache" in line
    with pytest.raises(WorkStarted):     # --no-cache needs no cache folder
        _invoke(["--debug", "run", scene, "--out", tmp_path / "out", "--no-cache", "--rig-model", "nominal"],
                catch_exceptions=False)


# ---- item 3: memory ---------------------------------------------------------------------------------------------

def test_05_a_scene_too_big_for_the_memory(tmp_path, no_work):
    big = tmp_path / "big.toml"
    big.write_text(tiny_scene_text().replace("resolution = [48, 36]", "resolution = [100000, 100000]"))
    result = _invoke(["run", big, "--out", tmp_path / "out", "--rig-model", "nominal"])
    line = _one_line_error(result)
    assert re.search(r"needs about [\d.]+ TB of memory .* more than the limit of [\d.]+ [GMT]B", line), line
    assert not (tmp_path / "out").exists()
    with pytest.raises(WorkStarted):            # --max-memory lets a big machine run it
        _invoke(["--debug", "run", big, "--out", tmp_path / "out", "--rig-model", "nominal", "--max-memory",
                 "1000T"], catch_exceptions=False)
    assert "--max-memory" in _one_line_error(_invoke(["run", big, "--max-memory", "plenty"]))


# ---- item 7: escaping, encodings, option ranges, --quick, calibration files ---------------------------------

def test_06_bracketed_text_survives(tmp_path, no_work):
    missing = tmp_path / "take[v2].toml"
    assert f"{missing}: no such file" in _one_line_error(_invoke(["run", missing]))
    empty = tmp_path / "empty[1].toml"
    empty.write_text("[light]\nposition = [0.3, 0.1, 0.0]\n")
    line = _one_line_error(_invoke(["run", empty]))
    assert "empty[1].toml" in line and "[[real]]" in line and "[[synthetic]]" in line


def test_07_bom_accepted_non_utf8_named(tmp_path, no_work):
    bom = tmp_path / "bom.toml"
    bom.write_bytes(b"\xef\xbb\xbf" + tiny_scene_text().encode())
    with pytest.raises(WorkStarted):
        _invoke(["--debug", "run", bom, "--out", tmp_path / "o", "--rig-model", "nominal"], catch_exceptions=False)
    latin = tmp_path / "latin.toml"
    latin.write_bytes(tiny_scene_text().replace("red block", "bloc \u00e9").encode("latin-1"))
    line = _one_line_error(_invoke(["run", latin]))
    assert "latin.toml: <encoding>: not UTF-8 text: byte 0xe9 on line" in line


@pytest.mark.parametrize("args, words", [
    (["--truth-seed", "-1"], "'--truth-seed'"),
    (["--gt-spp", "-5"], "'--gt-spp'"),
    (["--gt-spp", "0"], "'--gt-spp'"),
    (["--bounces", "21"], "'--bounces'"),
    (["--bounces", "two"], "'--bounces'"),
    (["--renderer", "magic"], "--renderer"),
    (["--rig-model", "psychic"], "--rig-model"),
    (["--colour", "red"], "--colour"),
    (["--cluster", "local", "--no-quiet-reference"],
     "--cluster: lft run spreads a quiet reference's rounds over it; add --quiet-reference"),
    (["--workers", "2"], "--workers: needs --cluster"),
])
def test_08_options_have_ranges(scene, tmp_path, no_work, args, words):
    line = _one_line_error(_invoke(["run", scene, "--out", tmp_path / "o", *args]))
    assert words in line


def test_09_seeds_and_other_commands_ranges(scene, tmp_path, no_work):
    assert "--seeds" in _one_line_error(_invoke(["calibrate", "seeds", "--seeds", "1,-2"]))
    assert "--square-mm" in _one_line_error(_invoke(["calibrate", "intrinsics", scene, "--square-mm", "-3"]))
    assert "'--tries'" in _one_line_error(_invoke(["calibrate", "latency", scene, "--tries", "0"]))
    assert "'--truth-seed'" in _one_line_error(_invoke(["calibrate", scene, "--truth-seed", "-1"]))


def test_10_quick_on_a_small_scene(tmp_path, no_work):
    small = tmp_path / "small.toml"
    small.write_text(tiny_scene_text(view=(24, 18)))
    line = _one_line_error(_invoke(["run", small, "--quick"]))
    assert "--quick divides every device by 4" in line and "view.resolution [24, 18] gives 6 x 4" in line
    assert "run it without --quick" in line
    with pytest.raises(WorkStarted):
        _invoke(["--debug", "run", small, "--out", tmp_path / "o", "--rig-model", "nominal"], catch_exceptions=False)


def test_11_calibration_file_errors_name_the_field(scene, tmp_path, no_work):
    from lftransfer.scenes import load_scene

    good = nominal_calibration(load_scene(scene)).write(tmp_path / "calibration.json")
    data = json.loads(good.read_text())
    del data["radiometry"]
    data["lens_array"]["colour"] = "blue"
    bad = tmp_path / "cal[old].json"
    bad.write_text(json.dumps(data))
    result = _invoke(["run", scene, "--calibration", bad, "--out", tmp_path / "o"])
    line = _one_line_error(result)
    assert f"{bad}: lens_array.colour: unknown key" in line and "radiometry: required field is missing" in line
    with pytest.raises(WorkStarted):
        _invoke(["--debug", "run", scene, "--calibration", good, "--out", tmp_path / "o"], catch_exceptions=False)


# ---- the last line of defence, --debug ------------------------------------------------------------------------

def test_12_unexpected_errors_are_one_line_unless_debug(scene, tmp_path, monkeypatch):
    def broken(*args, **kwargs):
        raise ZeroDivisionError("float division by zero")

    monkeypatch.setattr("lftransfer.app.cli.run._run", broken)
    args = ["run", scene, "--out", tmp_path / "o", "--rig-model", "nominal"]
    line = _one_line_error(_invoke(args), code=1)
    assert line == "error: ZeroDivisionError: float division by zero (lft --debug ... shows the traceback)"
    result = _invoke([*args, "--debug"])                         # --debug anywhere on the line
    assert isinstance(result.exception, ZeroDivisionError)


# ---- item 9: help, native library messages (interrupted runs: test_run_folder.py) ---------------------------------------------

def test_13_help_shows_flags_without_types_and_the_calibrate_scene_form():
    for args in (["run", "--help"], ["demo", "--help"], ["calibrate", "rig", "--help"], ["--help"]):
        result = _invoke(args, env={"COLUMNS": "160"})
        assert result.exit_code == 0 and "<bool>" not in result.output, result.output
    run_help = _invoke(["run", "--help"], env={"COLUMNS": "160"}).output
    assert re.search(r"--quick\s+Quarter resolution", run_help) and re.search(r"--out\s+DIR", run_help)
    assert re.search(r"--out\s+FILE\.json", _invoke(["calibrate", "rig", "--help"], env={"COLUMNS": "160"}).output)
    calibrate_help = _invoke(["calibrate", "--help"], env={"COLUMNS": "160"}).output
    assert "lft calibrate SCENE.toml" in calibrate_help and "--out FILE.json" in calibrate_help


def test_14_no_libpng_words_on_the_terminal(tmp_path, capfd):
    ok, buf = cv2.imencode(".png", (np.random.default_rng(0).random((50, 60)) * 255).astype(np.uint8))
    data = bytearray(buf.tobytes())
    for i in range(60, len(data) - 20, 7):
        data[i] ^= 0x55
    png = tmp_path / "corrupt.png"
    png.write_bytes(bytes(data))
    capfd.readouterr()
    for args in (["calibrate", "lenslets", png, "--out", tmp_path / "c.csv"],
                 ["calibrate", "intrinsics", png, "--square-mm", "20", "--out", tmp_path / "i.json"]):
        line = _one_line_error(_invoke(args))
        assert "corrupt.png" in line
    captured = capfd.readouterr()
    assert "libpng" not in captured.err and "WARN" not in captured.err, captured.err


def test_15_a_calibration_that_cannot_measure_the_rig(scene, tmp_path, monkeypatch):
    """A step that cannot measure the rig from its images (here: no chessboard found) is one line, exit code 1,
    naming the step and what to try."""
    from lftransfer.calibration.pose import PoseError

    def blind(*args, **kwargs):
        raise PoseError("the printed 7 x 5 chessboard was not found in the view camera image")

    monkeypatch.setattr("lftransfer.runs.rigs.calibrate_rig", blind)
    line = _one_line_error(_invoke(["calibrate", scene, "--out", tmp_path / "cal.json"]), code=1, progress=True)
    assert "calibration failed: the printed 7 x 5 chessboard was not found" in line
    assert "view camera 48 x 36" in line and "--rig-model nominal" in line
    out = tmp_path / "run"
    line = _one_line_error(_invoke(["run", scene, "--out", out]), code=1, progress=True)
    assert "calibration failed" in line and str(out / "status.json") in line

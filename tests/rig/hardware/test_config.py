"""The rig file: loading, one-line errors naming file and field, values written back keeping the rest."""

from __future__ import annotations

import tomllib
from importlib import resources
from pathlib import Path

import pytest

from lftransfer.rig.hardware import HardwareRigConfig, RigFileError, load_rig_file, write_rig_value

RIG = """\
# a test rig
[lf_camera]
source = "frames/%04d.png"   # an image sequence
width = 64
height = 48
bits = 12

[view_camera]
source = 0
width = 32
height = 24
response_gamma = [2.2, 2.0, 1.8]
radiance_scale = 3.5

[projector]
display = 1
width = 1024
height = 768
settle_s = 0.25    # written by the latency calibration
drop_frames = 2
"""


def _write(tmp_path: Path, text: str, name: str = "rig.toml") -> Path:
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return path


def test_01_valid_file_loads(tmp_path):
    path = _write(tmp_path, RIG)
    rig = load_rig_file(path)
    assert isinstance(rig, HardwareRigConfig) and rig.source == path.resolve()
    assert rig.lf_camera.kind == "images" and not rig.lf_camera.live
    assert rig.lf_camera.source == str(tmp_path.resolve() / "frames/%04d.png")     # relative to the file
    assert rig.lf_camera.levels == 4095 and rig.lf_camera.timeout_s == 5.0 and rig.lf_camera.frames == 1
    assert rig.view_camera.kind == "index" and rig.view_camera.live
    assert rig.view_camera.gamma_rgb == (2.2, 2.0, 1.8) and rig.view_camera.radiance_scale == 3.5
    assert rig.projector.settle_s == 0.25 and rig.projector.drop_frames == 2 and rig.projector.bits == 8
    info = rig.info
    assert info.lf_camera == (64, 48) and info.lf_camera_bits == 12 and info.projector == (1024, 768)
    assert info.view == (32, 24) and info.kind == "hardware" and info.projector_shape == (768, 1024)


def test_02_example_rig_file_is_valid():
    path = Path(str(resources.files("lftransfer.rig.hardware") / "example_rig.toml"))
    rig = load_rig_file(path)
    assert rig.lf_camera.kind == "genicam" and rig.lf_camera.serial == "21234567"
    assert rig.view_camera.kind == "v4l2" and rig.projector.display == 1
    # every field of every table has a comment above it
    lines = path.read_text().splitlines()
    for i, line in enumerate(lines):
        if "=" in line and not line.lstrip().startswith("#"):
            assert lines[i - 1].lstrip().startswith("#"), f"no comment above {line!r}"


@pytest.mark.parametrize("old, new, expected", [
    ("bits = 12", "bits = 20", r"rig\.toml: lf_camera\.bits: Input should be less than or equal to 16, found 20$"),
    ("width = 64", "width = \"64\"", r"rig\.toml: lf_camera\.width: expected a number, found str '64'$"),
    ("display = 1", "display = -1", r"rig\.toml: projector\.display: Input should be greater than or equal to 0"),
    ("settle_s = 0.25", "settle = 0.25", r"rig\.toml: projector\.settle: unknown key"),
    ("source = 0", "source = 1.5", r"rig\.toml: view_camera\.source: expected a device index \(an integer\)"),
    ("source = 0", "source = \"genicam:123\"", r"rig\.toml: view_camera: a genicam: source needs cti"),
    ("radiance_scale = 3.5", "radiance_scale = 0", r"rig\.toml: view_camera\.radiance_scale: Input should be "
                                                   r"greater than 0, found 0$"),
    ("height = 48\n", "", r"rig\.toml: lf_camera\.height: required field is missing$"),
    ("[projector]", "[projector", r"rig\.toml: <toml>: malformed TOML"),
])
def test_03_bad_fields_give_one_line_errors(tmp_path, old, new, expected):
    assert old in RIG
    path = _write(tmp_path, RIG.replace(old, new, 1))
    with pytest.raises(RigFileError, match=expected) as err:
        load_rig_file(path)
    message = str(err.value)
    assert "\n" not in message and message.startswith(str(path))


def test_04_missing_file(tmp_path):
    with pytest.raises(RigFileError, match=r"nope\.toml: cannot read the rig file"):
        load_rig_file(tmp_path / "nope.toml")


def test_05_settle_written_back_keeps_the_rest(tmp_path):
    path = _write(tmp_path, RIG)
    before = path.read_text()
    rig = write_rig_value(path, "projector.settle_s", 0.137)
    after = path.read_text()
    assert rig.projector.settle_s == 0.137 and load_rig_file(path).projector.settle_s == 0.137
    changed = [(a, b) for a, b in zip(before.splitlines(), after.splitlines()) if a != b]
    assert changed == [("settle_s = 0.25    # written by the latency calibration",
                        "settle_s = 0.137    # written by the latency calibration")]
    assert len(before.splitlines()) == len(after.splitlines())
    assert not list(tmp_path.glob(".rig.*"))                   # no temporary file left behind


def test_06_missing_key_and_missing_table_are_added(tmp_path):
    path = _write(tmp_path, RIG.replace("settle_s = 0.25    # written by the latency calibration\n", ""))
    write_rig_value(path, "projector.settle_s", 0.05)
    text = path.read_text()
    assert "settle_s = 0.05\n" in text and text.startswith("# a test rig\n")
    assert tomllib.loads(text)["projector"]["drop_frames"] == 2
    assert load_rig_file(path).projector.settle_s == 0.05

    no_table = RIG[:RIG.index("[view_camera]")] + "[projector]\nwidth = 1024\nheight = 768\n"
    path = _write(tmp_path, no_table, "rig2.toml")
    with pytest.raises(RigFileError, match=r"view_camera\.source: required field is missing"):
        write_rig_value(path, "view_camera.frames", 8)      # the result would still be invalid
    path.write_text(no_table + '[view_camera]\nsource = 0\nwidth = 32\nheight = 24\n')
    write_rig_value(path, "projector.settle_s", 0.5)
    assert load_rig_file(path).projector.settle_s == 0.5
    assert path.read_text().count("[projector]") == 1


def test_07_inline_table_falls_back_to_a_full_rewrite(tmp_path):
    # an inline table (top-level keys stand before the first header): the line edit cannot set a key in it
    text = "projector = { width = 1024, height = 768, settle_s = 0.3 }\n" + RIG[:RIG.index("[projector]")]
    path = _write(tmp_path, text)
    write_rig_value(path, "projector.settle_s", 0.042)
    rig = load_rig_file(path)
    assert rig.projector.settle_s == 0.042 and rig.projector.width == 1024 and rig.lf_camera.bits == 12


def test_08_invalid_value_is_refused_and_file_unchanged(tmp_path):
    path = _write(tmp_path, RIG)
    with pytest.raises(RigFileError, match=r"projector\.settle_s: Input should be greater than or equal to 0"):
        write_rig_value(path, "projector.settle_s", -1.0)
    assert path.read_text() == RIG

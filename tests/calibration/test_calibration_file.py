"""The calibration file is validated like scene files: every field typed and ranged, unknown keys refused, one
line naming the file and the field; random and mutated files never end in anything else."""

from __future__ import annotations

import copy
import json
import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from lftransfer.calibration.light import LightFit
from lftransfer.calibration.rig import CalibrationFileError, load_calibration
from lftransfer.scenes import load_scene
from tests.small import nominal_calibration, write_tiny_scene
from tests.mutations import mutated as mutated_file


LIGHT = LightFit(position=(0.3012, 0.1189, 0.0021), start=(0.30, 0.12, 0.0), intensity_albedo=(1.6, 1.61, 1.59),
                 dark_ratio=0.2502, residual_rms=0.0012, std_mm=(0.005, 0.005, float("nan")), pixels=13000, boards=4)


@pytest.fixture(scope="module")
def setup(tmp_path_factory):
    """A tiny scene and a valid calibration file for it (its JSON data), with a measured point light."""
    d = tmp_path_factory.mktemp("calfile")
    scene = load_scene(write_tiny_scene(d / "tiny.toml"))
    cal = nominal_calibration(scene)
    cal.lights = [LIGHT]
    path = cal.write(d / "calibration.json")
    return scene, json.loads(path.read_text())


def _write(tmp_path, data, name="cal.json"):
    path = tmp_path / name
    path.write_text(json.dumps(data) if not isinstance(data, str) else data, encoding="utf-8")
    return path


def _error(tmp_path, scene, data, name="cal.json") -> str:
    with pytest.raises(CalibrationFileError) as info:
        load_calibration(_write(tmp_path, data, name), scene)
    return str(info.value)


def test_01_written_file_is_strict_json_and_reads_back(setup, tmp_path):
    scene, data = setup
    text = json.dumps(data)
    json.loads(text, parse_constant=lambda c: pytest.fail(f"non-strict JSON constant {c}"))
    cal = load_calibration(_write(tmp_path, data), scene)
    assert cal.model.array.rows == 3 and math.isnan(cal.pose.rms_px)     # null measurement -> NaN


def test_02_bom_is_accepted_and_non_utf8_is_named(setup, tmp_path):
    scene, data = setup
    bom = tmp_path / "bom.json"
    bom.write_bytes(b"\xef\xbb\xbf" + json.dumps(data).encode())
    assert load_calibration(bom, scene).model.array.cols == 4
    latin = tmp_path / "latin.json"
    latin.write_bytes(json.dumps(data).encode().replace(b'"hex"', b'"h\xe9x"'))
    with pytest.raises(CalibrationFileError, match=r"latin\.json: <encoding>: not UTF-8 text: byte 0xe9 on line 1"):
        load_calibration(latin, scene)


@pytest.mark.parametrize("mutate, field, words", [
    (lambda d: d.pop("radiometry"), "radiometry", "required field is missing"),
    (lambda d: d["radiometry"]["camera_gamma"].__setitem__(1, -2.2), "radiometry.camera_gamma[1]", "greater than 0"),
    (lambda d: d.__setitem__("colour", 1), "colour", "unknown key"),
    (lambda d: d["pose"].__setitem__("wobble", 1), "pose.wobble", "unknown key"),
    (lambda d: d["lf_camera"]["lenslets"][3].__setitem__("k9", 0), "lf_camera.lenslets[3].k9", "unknown key"),
    (lambda d: d["lens_array"].__setitem__("rows", "3"), "lens_array.rows", "valid integer"),
    (lambda d: d["lens_array"].__setitem__("pitch_m", True), "lens_array.pitch_m", "valid number"),
    (lambda d: d["projector"].__setitem__("homography", [[0, 0, 0]] * 3), "projector.homography", "invertible"),
    (lambda d: d["radiometry"]["vignetting"]["coeffs"].append(0.5), "radiometry.vignetting", "1 coefficients"),
    (lambda d: d.__setitem__("format", "lftransfer-calibration/0"), "format", "expected 'lftransfer-calibration/1'"),
    (lambda d: d["lens_array"].__setitem__("cols", 5), "lens_array", "but the scene's rig has 3 x 4"),
    (lambda d: d["lf_camera"].__setitem__("width", 320), "lf_camera.width", "but the scene's rig has 160 x 120"),
    (lambda d: d["projector"]["lenslets"].pop(), "projector.lenslets", "11 lenslet cameras"),
    (lambda d: d["radiometry"]["vignetting"].__setitem__("shape", [60, 80]), "radiometry.vignetting.shape",
     "LF camera is 120 x 160"),
    (lambda d: d["light"].pop("position_m"), "light.position_m", "required field is missing"),
    (lambda d: d["light"].__setitem__("position_m", [0.3, 0.1]), "light.position_m", "at least 3 items"),
    (lambda d: d["light"]["position_m"].__setitem__(2, "z"), "light.position_m[2]", "valid number"),
    (lambda d: d["light"].__setitem__("colour", 1), "light.colour", "unknown key"),
    (lambda d: d["light"].__setitem__("pixels", -1), "light.pixels", "greater than or equal to 0"),
])
def test_03_errors_name_the_file_and_the_field(setup, tmp_path, mutate, field, words):
    scene, data = setup
    data = copy.deepcopy(data)
    mutate(data)
    message = _error(tmp_path, scene, data, "take[v2].json")
    assert message.startswith(f"{tmp_path / 'take[v2].json'}: {field}"), message
    assert words in message, message
    assert "\n" not in message


def test_04_not_json_or_not_an_object(setup, tmp_path):
    scene, _ = setup
    assert "<json>: malformed JSON" in _error(tmp_path, scene, '{"format": ')
    assert "<calibration>: expected a JSON object" in _error(tmp_path, scene, "[1, 2]")
    with pytest.raises(CalibrationFileError, match=r"nope\.json: cannot read the calibration file"):
        load_calibration(tmp_path / "nope.json", scene)


# ---- property test: random and mutated files ----------------------------------------------------------------

_json_leaf = st.one_of(st.none(), st.booleans(), st.integers(-10**6, 10**6), st.text(max_size=8),
                       st.floats(allow_nan=True, allow_infinity=True))
_json_value = st.recursive(_json_leaf, lambda inner: st.one_of(st.lists(inner, max_size=4),
                                                             st.dictionaries(st.text(max_size=6), inner, max_size=4)),
                           max_leaves=8)


_FILE_LEVEL = ("<json>", "<encoding>", "<calibration>", "format", "lens_array", "pose", "lf_camera", "projector",
               "radiometry", "lenslet_centres", "distortion", "projector_mapping", "light")


def _check(message: str, name: str, data=None) -> None:
    """One line that starts with the file's name, then the field (a top-level key of the file, a schema section,
    or <json>/<encoding>/<calibration> for the file as a whole)."""
    assert message.startswith(f"{name}: "), message
    rest = message[len(name) + 2:]
    tops = list(_FILE_LEVEL) + (list(data) if isinstance(data, dict) else []) + ["["]
    assert any(rest.startswith(f"{t}") for t in tops), message
    assert "\n" not in message


@settings(max_examples=int(__import__("os").environ.get("N_EX", 60)), deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture,
                                                                  HealthCheck.too_slow])
@given(data=st.data())
def test_05_mutated_files_never_escape_the_loader(setup, tmp_path, data):
    """Mutated calibration files (values replaced by random JSON, keys deleted or added) either load or raise the
    project's error naming the file and a field: never a traceback of another kind."""
    scene, base = setup
    mutated = data.draw(mutated_file(st.just(base), _json_value))
    path = tmp_path / "cal[x].json"
    path.write_text(json.dumps(mutated), encoding="utf-8")
    try:
        load_calibration(path, scene)
    except CalibrationFileError as exc:
        _check(str(exc), str(path), mutated)


@settings(max_examples=int(__import__("os").environ.get("N_EX", 60)), deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(blob=st.one_of(st.binary(max_size=200), st.text(max_size=200).map(str.encode),
                      _json_value.map(lambda v: json.dumps(v).encode())))
def test_06_random_bytes_never_escape_the_loader(setup, tmp_path, blob):
    scene, _ = setup
    path = tmp_path / "random.json"
    path.write_bytes(blob)
    with pytest.raises(CalibrationFileError) as info:
        load_calibration(path, scene)
    try:
        parsed = json.loads(blob.decode("utf-8-sig"))
    except ValueError:
        parsed = None
    _check(str(info.value), str(path), parsed)


@settings(max_examples=int(__import__("os").environ.get("N_EX", 30)), deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(cut=st.integers(0, 8000), flip=st.integers(0, 255))
def test_07_truncated_and_corrupted_bytes(setup, tmp_path, cut, flip):
    scene, base = setup
    raw = json.dumps(base).encode()
    cut = min(cut, len(raw) - 1)
    for blob in (raw[:cut], raw[:cut] + bytes([flip]) + raw[cut + 1:]):
        path = tmp_path / "cut.json"
        path.write_bytes(blob)
        try:
            load_calibration(path, scene)
        except CalibrationFileError as exc:
            _check(str(exc), str(path))


def test_08_the_light_section_is_optional(setup, tmp_path):
    """The measured point light reads back exactly (NaN measurements as null); a file without the section (written
    before the step existed, or for a scene without a light) loads, and the scene file's light then stands."""
    scene, data = setup
    assert data["light"]["std_mm"][2] is None and "lights" not in data
    cal = load_calibration(_write(tmp_path, data), scene)
    (light,) = cal.lights
    np.testing.assert_array_equal(light.position, LIGHT.position)
    assert light.boards == 4 and light.pixels == 13000 and math.isnan(light.std_mm[2])
    assert light.residual_rms == LIGHT.residual_rms and light.shift_mm == pytest.approx(LIGHT.shift_mm)
    assert cal.light_positions(scene) == [tuple(LIGHT.position.tolist())]
    again = json.loads(cal.write(tmp_path / "again.json").read_text())
    assert again["light"] == data["light"]
    old = {k: v for k, v in data.items() if k != "light"}
    cal = load_calibration(_write(tmp_path, old, "old.json"), scene)
    assert cal.lights == [] and "light" not in cal.to_json()
    assert cal.light_positions(scene) == [tuple(scene.lights[0].position)]
    minimal = {**old, "light": {"position_m": [0.31, 0.12, 0.0]}}
    assert load_calibration(_write(tmp_path, minimal, "minimal.json"), scene).light_positions(scene) == \
        [(0.31, 0.12, 0.0)]


def test_09_several_lights(setup, tmp_path):
    """A scene with two point lights: its file holds ``lights`` (one entry per light, in the scene's order) and
    reads back; a count that does not fit the scene, or both sections, is an error naming the field."""
    from lftransfer.scenes import with_overrides

    scene, data = setup
    two = with_overrides(scene, lights=[*scene.lights, {"position": [-0.1, 0.1, 0.0], "intensity": [1, 1, 1]}])
    cal = load_calibration(_write(tmp_path, data), scene)
    second = LightFit(position=(-0.1013, 0.1, 0.001), start=(-0.1, 0.1, 0.0), intensity_albedo=(0.8, 0.8, 0.8),
                      dark_ratio=0.25, residual_rms=0.001, std_mm=(0.01, 0.01, 0.02), pixels=9000, boards=4)
    cal.lights = [LIGHT, second]
    written = json.loads(cal.write(tmp_path / "two.json").read_text())
    assert "light" not in written and len(written["lights"]) == 2
    back = load_calibration(tmp_path / "two.json", two)
    assert back.light_positions(two) == [tuple(LIGHT.position.tolist()), tuple(second.position.tolist())]
    assert "lights: 2 point light(s) measured, but the scene has 1" in _error(tmp_path, scene, written)
    assert "light: 1 point light(s) measured, but the scene has 2" in _error(tmp_path, two, data)
    both = {**written, "light": data["light"]}
    assert "give light (one point light) or lights (several), not both" in _error(tmp_path, two, both)
    bad = copy.deepcopy(written)
    bad["lights"][1]["position_m"] = [0.1, 0.2]
    assert "lights[1].position_m" in _error(tmp_path, two, bad)

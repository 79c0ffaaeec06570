"""Reading scene files: any encoding problem, random or mutated file ends in one SceneError naming the file (and
the field where there is one), never in another exception."""

from __future__ import annotations

import os
import tomllib

import pytest
import tomli_w
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from lftransfer.scenes import SceneConfig, SceneError, builtin_scene, load_scene
from tests.small import tiny_scene_text
from tests.mutations import mutated

EXAMPLES = int(os.environ.get("LFT_HYPOTHESIS_EXAMPLES", 60))


def test_01_byte_order_mark_is_accepted(tmp_path):
    path = tmp_path / "bom.toml"
    path.write_bytes(b"\xef\xbb\xbf" + tiny_scene_text().encode())
    assert load_scene(path).rig.rows == 3


def test_02_non_utf8_names_the_file_the_line_and_the_byte(tmp_path):
    path = tmp_path / "latin1.toml"
    path.write_bytes(tiny_scene_text().replace('"red block"', '"bloc rouge \u00e9"').encode("latin-1"))
    with pytest.raises(SceneError) as info:
        load_scene(path)
    line = next(i for i, s in enumerate(tiny_scene_text().splitlines(), 1) if "red block" in s)
    assert str(info.value).startswith(f"{path}: <encoding>: not UTF-8 text: byte 0xe9 on line {line}, column ")
    assert "save the scene file as UTF-8" in str(info.value)


def test_03_utf16_file_is_named(tmp_path):
    path = tmp_path / "utf16.toml"
    path.write_bytes(tiny_scene_text().encode("utf-16"))
    with pytest.raises(SceneError, match=r"utf16\.toml: <encoding>: not UTF-8 text"):
        load_scene(path)


def test_04_a_folder_is_not_a_scene(tmp_path):
    with pytest.raises(SceneError, match="cannot read the scene file"):
        load_scene(tmp_path)


# ---- property test ----------------------------------------------------------------------------------------

_leaf = st.one_of(st.booleans(), st.integers(-10**9, 10**9), st.text(max_size=8),
                  st.floats(allow_nan=True, allow_infinity=True))
_value = st.recursive(_leaf, lambda inner: st.one_of(st.lists(inner, max_size=4),
                                                     st.dictionaries(st.text(max_size=6), inner, max_size=3)),
                      max_leaves=6)
_BASES = [tomllib.loads(tiny_scene_text()), tomllib.loads(builtin_scene("fig4").read_text())]
_SCENE_KEYS = ("<toml>", "<encoding>", "<scene>", "source", "[") + tuple(SceneConfig.model_fields)


def _check(message: str, path, data=None) -> None:
    """The project's wording: the file, then a field (or <toml>/<encoding>/<scene>), on one line."""
    name = str(path)
    assert message.startswith(f"{name}: "), message
    rest = message[len(name) + 2:]
    tops = _SCENE_KEYS + (tuple(data) if isinstance(data, dict) else ())
    assert any(rest.startswith(t) for t in tops), message
    assert "\n" not in message, message


@settings(max_examples=EXAMPLES, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture,
                                                                       HealthCheck.too_slow])
@given(data=mutated(st.sampled_from(_BASES), _value))
def test_05_mutated_scenes_never_escape_the_loader(tmp_path, data):
    """Scene files with values replaced by random TOML values, tables and keys deleted or added."""
    path = tmp_path / "take[v2].toml"
    try:
        path.write_text(tomli_w.dumps(data), encoding="utf-8")
    except (TypeError, ValueError):         # a value TOML cannot hold (e.g. a mixed array in old tomli_w)
        return
    try:
        load_scene(path)
    except SceneError as exc:
        _check(str(exc), path, data)


@settings(max_examples=EXAMPLES, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(blob=st.one_of(st.binary(max_size=300), st.text(max_size=300).map(str.encode)),
       base=st.sampled_from([tiny_scene_text().encode(), b""]), cut=st.integers(0, 2000))
def test_06_random_and_corrupted_bytes_never_escape_the_loader(tmp_path, blob, base, cut):
    """Random bytes, random text, and a valid file with random bytes spliced in or cut short."""
    path = tmp_path / "random.toml"
    cut = min(cut, len(base))
    for content in (blob, base[:cut] + blob + base[cut:], base[:cut]):
        path.write_bytes(content)
        try:
            load_scene(path)
        except SceneError as exc:
            try:
                parsed = tomllib.loads(content.decode("utf-8-sig"))
            except (ValueError, UnicodeDecodeError):
                parsed = None
            _check(str(exc), path, parsed)

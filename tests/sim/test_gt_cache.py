"""The ground-truth cache checks every entry on read: a corrupt, truncated, swapped or unchecked entry is
rendered again with a warning, never trusted and never a Mitsuba I/O error."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest

from lftransfer.sim.gt_cache import CacheProblem, entry_paths, read_entry, write_entry

A, B = "a" * 64, "b" * 64
SHAPE = (6, 8, 20)


def _stack(seed: int) -> np.ndarray:
    return np.random.default_rng(seed).random(SHAPE, dtype=np.float32)


def test_01_written_entry_reads_back_exactly(variant):
    stack = _stack(1)
    write_entry(A, stack)
    image, meta = entry_paths(A)
    assert json.loads(meta.read_text())["inputs_sha256"] == A
    back = read_entry(A, SHAPE)
    assert isinstance(back, np.ndarray) and np.array_equal(back, stack)
    assert read_entry("c" * 64, SHAPE) is None                   # no entry: nothing to say


@pytest.mark.parametrize("damage, words", [
    (lambda img, meta: img.write_bytes(img.read_bytes()[: len(img.read_bytes()) // 2]), "does not match its checksum"),
    (lambda img, meta: img.write_bytes(img.read_bytes()[:-9] + b"\x00" * 9), "does not match its checksum"),
    (lambda img, meta: meta.unlink(), "has no checksum file"),
    (lambda img, meta: meta.write_text("{"), "unreadable checksum file"),
    (lambda img, meta: (shutil.copyfile(entry_paths(B)[0], img), shutil.copyfile(entry_paths(B)[1], meta)),
     "belongs to other inputs"),
    (lambda img, meta: shutil.copyfile(entry_paths(B)[0], img), "does not match its checksum"),
])
def test_02_bad_entries_are_reported_not_trusted(variant, damage, words):
    write_entry(A, _stack(1))
    write_entry(B, _stack(2))
    image, meta = entry_paths(A)
    damage(image, meta)
    problem = read_entry(A, SHAPE)
    assert isinstance(problem, CacheProblem), problem
    assert words in problem.reason and str(image) in problem.message()
    assert problem.message().endswith("rendering it again")


def test_03_an_entry_of_another_shape_is_not_used(variant):
    write_entry(A, _stack(1))
    problem = read_entry(A, (6, 9, 20))
    assert isinstance(problem, CacheProblem) and "expected (6, 9, 20)" in problem.reason


def test_04_render_ground_truth_rerenders_a_corrupt_entry_with_a_warning(variant, tmp_path):
    """Through the renderer: a truncated entry gives one warning, the same images as a fresh render, and a
    repaired entry."""
    from lftransfer.scenes import load_scene, with_overrides
    from lftransfer.sim.ground_truth import _inputs_hash, render_ground_truth
    from tests.small import write_tiny_scene

    scene = load_scene(write_tiny_scene(tmp_path / "tiny.toml", view=(16, 12)))
    scene = with_overrides(scene, render={"gt_spp": 2})
    said: list[str] = []
    first = render_ground_truth(scene, spp=2, warn=said.append)
    image, _ = entry_paths(_inputs_hash(scene, 2, (1, 2)))
    assert image.exists() and not said
    image.write_bytes(image.read_bytes()[:100])
    again = render_ground_truth(scene, spp=2, warn=said.append)
    assert len(said) == 1 and str(image) in said[0] and "checksum" in said[0]
    assert np.array_equal(again.union, first.union)
    assert isinstance(read_entry(_inputs_hash(scene, 2, (1, 2)), (12, 16, 20)), np.ndarray)
    render_ground_truth(scene, spp=2, warn=said.append)           # the repaired entry is read without a word
    assert len(said) == 1

"""Hypothesis strategy shared by the loaders' property tests: a parsed file with a few keys replaced, deleted or
added (scene TOML in tests/scenes/test_loading.py, calibration JSON in tests/calibration/test_calibration_file.py)."""

from __future__ import annotations

import copy

from hypothesis import strategies as st


def positions(data, prefix=()):
    """Every key path in nested dicts and lists (the first three items of a list), the empty path first."""
    yield prefix
    if isinstance(data, dict):
        for k, v in data.items():
            yield from positions(v, prefix + (k,))
    elif isinstance(data, list):
        for i, v in enumerate(data[:3]):
            yield from positions(v, prefix + (i,))


@st.composite
def mutated(draw, bases, values):
    """One of ``bases`` (a strategy of parsed files) with 1 to 3 values replaced by ``values``, deleted, or
    added beside them."""
    data = copy.deepcopy(draw(bases))
    for _ in range(draw(st.integers(1, 3))):
        paths = [p for p in positions(data) if p]
        if not paths:
            break
        path = draw(st.sampled_from(paths))
        parent = data
        for key in path[:-1]:
            parent = parent[key]
        action = draw(st.sampled_from(["replace", "delete", "add"]))
        if action == "replace":
            parent[path[-1]] = draw(values)
        elif action == "delete":
            del parent[path[-1]]
        elif isinstance(parent, dict):
            parent[draw(st.text(min_size=1, max_size=6))] = draw(values)
        else:
            parent.append(draw(values))
    return data

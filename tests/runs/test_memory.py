"""The memory a run needs is estimated from the scene before any work and refused above the limit."""

from __future__ import annotations

import pytest

from lftransfer.runs.memory import (MemoryLimitError, available_memory, check_memory, estimate_memory, format_bytes,
                                   parse_size)
from lftransfer.scenes import quick_scene
from lftransfer.scenes import builtin_scene, load_scene, with_overrides


def test_01_estimate_grows_with_the_scene():
    fig4 = load_scene(builtin_scene("fig4"))
    quick = estimate_memory(quick_scene(fig4))
    full = estimate_memory(fig4)
    assert 0.3e9 < quick.total < 0.8e9            # lft demo --quick peaked at 0.48 GB
    assert 2e9 < full.total < 8e9 and sum(full.parts.values()) == full.total
    assert estimate_memory(fig4, calibrate=False).total < full.total
    huge = estimate_memory(with_overrides(fig4, view={"resolution": [100000, 100000]}))
    assert huge.total > 5e12 and huge.largest().startswith("the view camera")


def test_02_refused_with_the_estimate_and_the_limit():
    huge = estimate_memory(with_overrides(load_scene(builtin_scene("fig4")), view={"resolution": [100000, 100000]}))
    with pytest.raises(MemoryLimitError) as info:
        check_memory(huge)
    text = str(info.value)
    assert f"about {format_bytes(huge.total)}" in text and format_bytes(available_memory()) in text
    assert "--max-memory" in text
    assert check_memory(huge, limit=10 ** 15) == 10 ** 15          # a big machine may say so


@pytest.mark.parametrize("text, value", [("64G", 64e9), ("512M", 512e6), ("1.5 GiB", 1.5 * 2 ** 30),
                                         ("2000000", 2e6), ("16gb", 16e9)])
def test_03_sizes(text, value):
    assert parse_size(text) == int(value)


@pytest.mark.parametrize("text", ["", "lots", "-1G", "0", "12X", "1e9"])
def test_04_bad_sizes(text):
    with pytest.raises(ValueError, match="expected a"):
        parse_size(text)

"""The projector window under Xvfb: pixel-exact images, clear errors for a missing display or monitor."""

from __future__ import annotations

import time

import numpy as np
import pytest

from lftransfer.rig.base import RigError
from lftransfer.rig.hardware.config import ProjectorConfig
from lftransfer.rig.hardware.projector import ProjectorWindow

from .conftest import SCREEN

QUICK_S = 3.0         # a bound on a hang, not a speed benchmark


def _config(**kw):
    return ProjectorConfig(width=SCREEN[0], height=SCREEN[1], timeout_s=10.0, **kw)


def test_01_random_image_is_shown_pixel_exactly(display):
    rng = np.random.default_rng(0)
    with ProjectorWindow(_config()) as window:
        assert window.framebuffer_bits == 8
        assert window.screenshot().max() == 0                  # opens black
        for _ in range(2):
            image = rng.integers(0, 256, (SCREEN[1], SCREEN[0], 3), dtype=np.uint8)
            before = time.monotonic()
            presented = window.show(image)
            assert before <= presented <= time.monotonic()
            shot = window.screenshot()
            assert shot.dtype == np.uint8 and shot.shape == image.shape
            assert np.abs(shot.astype(int) - image).max() <= 1
        with pytest.raises(ValueError, match="projector image must be"):
            window.show(np.zeros((10, 10, 3), np.uint8))
    with pytest.raises(RigError, match=r"projector \(display 0\): the projector window is closed"):
        window.show(image)
    window.close()                                               # idempotent


def test_02_sixteen_bit_projector_rounds_to_the_display(display):
    rng = np.random.default_rng(1)
    image = rng.integers(0, 1024, (SCREEN[1], SCREEN[0], 3), dtype=np.uint16)
    with ProjectorWindow(_config(bits=10)) as window:
        window.show(image)
        shot = window.screenshot()
    # an 8-bit display keeps the top 8 of the 10 bits: within 1023 / 255 / 2 codes, plus rounding
    assert shot.dtype == np.uint16 and np.abs(shot.astype(int) - image).max() <= 3


def test_03_display_index_that_does_not_exist(display):
    start = time.monotonic()
    with pytest.raises(RigError, match=r"projector \(display 1\): opening the projector window: there is no "
                                        r"display 1; the window system has 1 monitor"):
        ProjectorWindow(_config(display=1))
    assert time.monotonic() - start < QUICK_S


def test_04_monitor_of_another_size(display):
    with pytest.raises(RigError, match=r"projector \(display 0\): .* runs at 1024x768 and offers no 800x600 mode"):
        ProjectorWindow(ProjectorConfig(width=800, height=600))


def test_05_no_display(monkeypatch):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    start = time.monotonic()
    with pytest.raises(RigError, match=r"projector \(display 0\): no display to open the projector window on"):
        ProjectorWindow(_config())
    assert time.monotonic() - start < QUICK_S


def test_06_unreachable_display(xvfb, monkeypatch):
    monkeypatch.setenv("DISPLAY", ":" + str(int(xvfb[1:]) + 37))     # no server there
    start = time.monotonic()
    with pytest.raises(RigError, match=r"projector \(display 0\): opening the projector window: the window system "
                                        r"cannot be reached"):
        ProjectorWindow(_config())
    assert time.monotonic() - start < QUICK_S

"""Fixtures of the hardware back-end's tests: a virtual X display (Xvfb) for the projector window."""

from __future__ import annotations

import shutil
import subprocess

import pytest

SCREEN = (1024, 768)


@pytest.fixture(scope="session")
def xvfb():
    """A private Xvfb server with one 1024x768x24 screen; yields its DISPLAY (":N").

    Skipped only where Xvfb is not installed (scripts/bootstrap.sh installs Debian's xvfb, so CI has it).
    """
    exe = shutil.which("Xvfb")
    if exe is None:
        pytest.skip("Xvfb is not installed (scripts/bootstrap.sh installs Debian's xvfb)")
    pytest.importorskip("glfw", reason="glfw is not installed (pip install -e '.[test]')")
    from lftransfer.sim.twin.display import start_xvfb

    try:
        name, proc = start_xvfb(*SCREEN)
    except RuntimeError as exc:
        pytest.fail(f"Xvfb did not start: {exc}")
    try:
        yield name
    finally:
        proc.terminate()
        try:
            proc.wait(timeout=5)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(timeout=5)


@pytest.fixture
def display(xvfb, monkeypatch):
    """DISPLAY set to the test X server (X11 GLFW build, GLX) for one test."""
    monkeypatch.setenv("DISPLAY", xvfb)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    monkeypatch.setenv("XDG_SESSION_TYPE", "x11")
    return xvfb

"""Fixtures of the hardware back-end's tests: a virtual X display (Xvfb) for the projector window."""

from __future__ import annotations

import os
import shutil
import subprocess
import time

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
    read_fd, write_fd = os.pipe()
    proc = subprocess.Popen([exe, "-displayfd", str(write_fd), "-screen", "0", f"{SCREEN[0]}x{SCREEN[1]}x24",
                             "-nolisten", "tcp", "-noreset"], pass_fds=(write_fd,),
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    os.close(write_fd)
    number = b""
    deadline = time.monotonic() + 10.0
    try:
        os.set_blocking(read_fd, False)
        while not number.endswith(b"\n") and time.monotonic() < deadline and proc.poll() is None:
            try:
                chunk = os.read(read_fd, 64)
            except BlockingIOError:
                time.sleep(0.02)
                continue
            if not chunk:
                break
            number += chunk
    finally:
        os.close(read_fd)
    if not number.strip().isdigit():
        proc.kill()
        err = proc.communicate(timeout=5)[1].decode(errors="replace")[-500:]
        pytest.fail(f"Xvfb did not start: {err}")
    try:
        yield f":{number.strip().decode()}"
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

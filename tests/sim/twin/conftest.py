"""Fixtures of the device twin's tests: ``lft twin serve`` as a separate process (its own Xvfb)."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import time
import urllib.request
from pathlib import Path

import pytest


class TwinProcess:
    """A running ``lft twin serve``: its rig file, manifest and URL."""

    def __init__(self, proc: subprocess.Popen, rig_file: Path, log: Path) -> None:
        self.proc, self.rig_file, self.log = proc, rig_file, log
        self.manifest = json.loads(rig_file.with_suffix(".json").read_text())
        self.url = self.manifest["url"]

    def status(self) -> dict:
        with urllib.request.urlopen(self.url + "/status", timeout=10) as answer:
            return json.loads(answer.read())

    def stop(self) -> None:
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(timeout=15)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(timeout=5)


def start_twin(tmp: Path, scene: str, *args: str, timeout_s: float = 120.0) -> TwinProcess:
    """Start ``lft twin serve SCENE --rig-file tmp/twin.toml ARGS`` and wait until its rig file is written.

    Skipped where Xvfb is not installed (scripts/bootstrap.sh installs it, so CI has it)."""
    if shutil.which("Xvfb") is None:
        pytest.skip("Xvfb is not installed (scripts/bootstrap.sh installs Debian's xvfb)")
    pytest.importorskip("av", reason="PyAV is not installed (pip install -e '.[test]')")
    pytest.importorskip("glfw", reason="glfw is not installed (pip install -e '.[test]')")
    tmp.mkdir(parents=True, exist_ok=True)
    rig_file, log = tmp / "twin.toml", tmp / "twin.log"
    env = {**os.environ, "LFT_VARIANT": os.environ.get("LFT_VARIANT", "llvm_ad_rgb")}
    proc = subprocess.Popen([sys.executable, "-m", "lftransfer", "twin", "serve", scene, "--rig-file",
                             str(rig_file), "--serve-for-s", "1800", *args], stdout=log.open("w"),
                            stderr=subprocess.STDOUT, env=env)
    deadline = time.monotonic() + timeout_s
    while not rig_file.with_suffix(".json").exists():
        if proc.poll() is not None or time.monotonic() > deadline:
            proc.kill()
            pytest.fail(f"the twin did not start: {log.read_text()[-2000:]}")
        time.sleep(0.2)
    return TwinProcess(proc, rig_file, log)


@pytest.fixture
def twin_factory(tmp_path):
    """Starts twins (``start(scene, *args)``) and stops them after the test."""
    started: list[TwinProcess] = []

    def start(scene: str, *args: str, name: str = "twin") -> TwinProcess:
        twin = start_twin(tmp_path / name, scene, *args)
        started.append(twin)
        return twin

    yield start
    for twin in started:
        twin.stop()

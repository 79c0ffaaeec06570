"""The simulated rig in a process of its own (lftransfer.sim.process): the same captures as in process, the
simulated rig's own methods forwarded, errors carried back, and a dead child named in one line."""

from __future__ import annotations

import os
import signal

import numpy as np
import pytest

from lftransfer.rig.base import RigError
from lftransfer.rig.requests import RealScene
from lftransfer.scenes import builtin_scene, load_scene, quick_scene
from lftransfer.settings import Overrides, SimulatorSettings, resolve_settings
from lftransfer.sim.oracle import open_simulated_rig
from lftransfer.sim.process import SimulatorProcess


@pytest.fixture(scope="module")
def scene():
    return quick_scene(load_scene(builtin_scene("fig5")))


def _pattern(info) -> np.ndarray:
    black = info.black()
    rng = np.random.default_rng(1)
    return (rng.random(black.shape) * 200).astype(black.dtype)


def test_01_captures_equal_the_simulated_rig_in_process(variant, scene):
    """The same frame's noise, real scene time and projection give the same codes and view, to the bit (the
    child renders with one Dr.Jit thread, this process with every core)."""
    rig, _oracle = open_simulated_rig(scene, 3, capture_spp=2)
    with SimulatorProcess(scene, 3, capture_spp=2, threads=1, nice=5) as child:
        assert child.info == rig.info
        got = []
        for r in (child, rig):
            r.start_frame(2)
            r.setup(RealScene(time_s=0.5))
            r.project(_pattern(r.info))
            got.append((r.capture_lf().codes, r.capture_view().radiance))
        assert np.array_equal(got[0][0], got[1][0])
        assert np.array_equal(got[0][1], got[1][1])
        # negative control: another frame's noise gives other codes
        child.start_frame(3)
        assert not np.array_equal(child.capture_lf().codes, got[1][0])
        assert child.noise_state().keys() == rig.noise_state().keys()
        assert child.cpu_seconds() > 0


def test_02_forwarded_methods_errors_and_the_real_objects(variant, scene):
    with SimulatorProcess(scene, None, capture_spp=1) as child:
        names = [o.name for o in child.real_objects]
        assert names == [o.name for o in scene.real]
        moved = [o.model_dump() for o in child.real_objects]
        moved[0]["translate"] = [moved[0]["translate"][0] + 0.01, *moved[0]["translate"][1:]]
        child.place_real(moved)
        assert child.real_objects[0].translate[0] == pytest.approx(moved[0]["translate"][0])
        with pytest.raises(TypeError, match="not a set-up request"):      # the child's error, its own type
            child.setup("a board")
        with pytest.raises(AttributeError, match="no 'calibrate'"):
            child.calibrate()
        child.capture_lf()                                                 # it still serves after an error
    with pytest.raises(RigError, match="was closed"):
        child.capture_lf()


def test_03_a_dead_simulator_is_named_in_one_line(variant, scene):
    child = SimulatorProcess(scene, None, capture_spp=1)
    os.kill(child.pid, signal.SIGKILL)
    for _ in range(2):                                   # the request in progress and every later one
        with pytest.raises(RigError) as raised:
            child.capture_lf()
        assert str(raised.value) == (f"the simulator process (pid {child.pid}) died (exit code -9) during "
                                     "capture_lf; the simulated rig is gone")
    child.close()
    assert child.cpu_seconds() is None


def test_04_settings_resolved_once_with_checked_bounds(scene):
    assert resolve_settings(scene, loop="decoupled").simulator == SimulatorSettings("process", threads=1, nice=7,
                                                                                    share=0.0)
    assert resolve_settings(scene, live=True, loop="sync").simulator.where == "thread"     # it waits for each capture
    assert resolve_settings(scene).simulator.where == "thread"
    assert resolve_settings(scene, Overrides(simulator_share=0.25), loop="decoupled").simulator.share == 0.25
    asked = Overrides(simulator="thread", simulator_threads=2, simulator_nice=0, simulator_share=0,
                      renderer_threads=1)
    assert resolve_settings(scene, asked).simulator == SimulatorSettings("thread", threads=2, nice=0, share=0.0,
                                                                        renderer_threads=1)
    for bad, field in ((dict(simulator_nice=20), "simulator_nice"), (dict(simulator_threads=0), "simulator_threads"),
                       (dict(simulator="gpu"), "simulator"), (dict(renderer_threads=True), "renderer_threads"),
                       (dict(simulator_share=0.95), "simulator_share"),
                       (dict(simulator_share=-0.1), "simulator_share"), (dict(simulator_share=True), "simulator_share")):
        with pytest.raises(ValueError, match=field):
            Overrides(**bad)
    with pytest.raises(ValueError, match="threads"):
        SimulatorProcess(scene, None, capture_spp=1, threads=0)


def test_05_a_paused_simulator_takes_no_core_and_resumes_where_it_stood(variant, scene):
    """pause() stops the child mid-capture: its CPU time stands still and the capture waits; after resume() the
    capture finishes with the same codes as one never paused (the negative control: it does run when resumed)."""
    import threading
    import time

    with SimulatorProcess(scene, None, capture_spp=1) as plain:
        with pytest.raises(RuntimeError, match="not started pausable"):
            plain.pause()
    with SimulatorProcess(scene, 3, capture_spp=8, threads=1, pausable=True) as child:
        child.start_frame(1)
        plain = child.capture_lf().codes
        child.start_frame(1)
        got = {}
        request = threading.Thread(target=lambda: got.update(codes=child.capture_lf().codes))
        request.start()
        time.sleep(0.05)
        assert child.busy
        child.pause()
        child.pause()                                            # idempotent
        time.sleep(0.2)                                          # the stop has landed
        before = child.cpu_seconds()
        time.sleep(0.6)
        assert child.cpu_seconds() == before                     # stopped: no CPU time at all
        assert request.is_alive() and "codes" not in got         # the capture waits
        child.resume()
        request.join(60)
        assert np.array_equal(got["codes"], plain)
        assert not child.busy
        child.pause()
        # a child closed while paused is let go on first, and ends
    assert child._process.poll() is not None


@pytest.mark.parametrize("pausable", [True, False])
def test_06_a_paused_simulator_dies_with_its_parent(tmp_path, pausable):
    """A parent that dies while its pausable simulator is stopped leaves no stopped orphan holding the scene's memory
    (the child asked Linux for a signal when its parent goes). The negative control: a child not started pausable,
    stopped from outside, does outlive its parent (killed here)."""
    import subprocess
    import sys
    import time

    script = tmp_path / "parent.py"
    script.write_text(
        "import os, signal\n"
        "from lftransfer.scenes import builtin_scene, load_scene, quick_scene\n"
        "from lftransfer.sim.process import SimulatorProcess\n"
        "child = SimulatorProcess(quick_scene(load_scene(builtin_scene('fig5'))), None, capture_spp=1, "
        f"pausable={pausable})\n"
        + ("child.pause()\n" if pausable else "os.kill(child.pid, signal.SIGSTOP)\n") +
        f"open({str(tmp_path / 'pid')!r}, 'w').write(str(child.pid))\n"
        "os._exit(3)\n")
    # files, not pipes: an orphan that outlives the parent would hold a pipe open
    with open(tmp_path / "stderr", "w") as err:
        done = subprocess.run([sys.executable, str(script)], stdout=subprocess.DEVNULL, stderr=err, timeout=300)
    assert done.returncode == 3, (tmp_path / "stderr").read_text()[-2000:]
    pid = int((tmp_path / "pid").read_text())

    def alive() -> bool:
        try:
            return open(f"/proc/{pid}/stat").read().rsplit(")", 1)[1].split()[0] != "Z"   # a zombie is dead
        except OSError:
            return False

    end = time.time() + (10 if pausable else 3)
    while time.time() < end and alive():
        time.sleep(0.1)
    try:
        assert alive() is not pausable, f"pid {pid}"
    finally:
        if alive():
            os.kill(pid, signal.SIGKILL)

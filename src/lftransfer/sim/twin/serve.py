"""The device twin: the simulated world as a separate process behind the interfaces a physical rig has.

:class:`Twin` puts together the world (:mod:`.world`: hidden real objects, true lens array and lights, operator
errors), the projector as the window system shows it (:mod:`.display`), the two cameras with their own clocks and
faults (:mod:`.cameras`) and the HTTP server (:mod:`.server`: streams, exposure control, operator endpoint). It
writes the rig file that ``--rig hardware:RIG.toml`` opens, and beside it the twin's manifest (``RIG.json``: the
scene, the truth seed and the settings), which ``lft twin score`` reads to render the ground truth of a run.

The rig file says what the cameras deliver: both send ``planar`` 16-bit frames (12-bit codes for the LF camera,
linear 16-bit for the view camera with ``response_gamma = 1`` and the ``radiance_scale`` of its full scale), the
projector is display 0 of the twin's X display, and set-ups go to the twin's operator endpoint. ``settle_s`` is
not the twin's latency (the rig has to measure it: ``lft calibrate latency``); it starts at the example rig
file's 0.1 s.

The twin never helps the pipeline: the rig file holds only what a rig's builder would write down without
measuring (device sizes, bit depths, URLs), and the hidden truth stays in this process and its manifest's seed.
"""

from __future__ import annotations

import json
import logging
import os
import subprocess
import threading
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Literal

import numpy as np

from lftransfer.imageio_utils import write_text
from lftransfer.sim.twin.cameras import CameraTiming, TwinCamera, planar
from lftransfer.sim.twin.display import ProjectorScreen, start_xvfb
from lftransfer.sim.twin.server import TwinServer
from lftransfer.sim.twin.world import TwinWorld

__all__ = ["Twin", "TwinOptions", "manifest_path"]

_log = logging.getLogger(__name__)

VIEW_HEADROOM = 16.0       # the view camera's full scale: this many times the brightest pixel of the real scene
VIEW_SPP = 16
"""Samples per view camera pixel of the twin's image of a state. A camera cannot render a capture at the samples a
request asks for (the in-process rig renders ``ViewCapture.quality``); the hardware rig averages that many frames
instead, and the twin's frames of one state are one image. So the twin renders each state at the quality the
calibration's photographs ask for (16: the pose's and the point light's boards), not the in-process rig's default
of 4 for plain captures: its board photographs are then as clean as in process, and its plain views cleaner."""


@dataclass(frozen=True)
class TwinOptions:
    """How the twin behaves (``lft twin serve``'s options).

    Attributes:
        truth_seed: seed of the hidden truth (None: the rig built exactly as its file says), as ``lft run``'s.
        lf_fps, view_fps: the cameras' frame rates.
        latency_ms: display-to-capture latency of both cameras, ms.
        jitter_ms: each frame's latency varies uniformly within +- this, ms.
        drop_rate: probability that a frame is lost.
        stop_after_s: a camera's stream stops this long after the twin started, or None.
        stop_camera: which camera stops ("lf", "view" or "both").
        down_for_s: the stopped stream comes back after this long, or None (never).
        projector_missing: the projector's display is missing (the rig file names an X display with no server).
        display: the X display the projector window goes to (":N"), or None: the twin starts its own Xvfb of the
            projector's size.
        host, port: where the twin listens (port 0: a free one).
        capture_spp: rays per LF camera pixel (None: the simulated rig's default, as ``lft run`` on it).
        view_spp: samples per view camera pixel of the image of each state (:data:`VIEW_SPP`; None: the simulated
            rig's default).
        settle_s: ``projector.settle_s`` written into a new rig file (not measured; ``lft calibrate latency`` does).
        camera_timeout_s: the rig file's cameras' ``timeout_s`` (above the longest render of a new state).
    """

    truth_seed: int | None = 0
    lf_fps: float = 7.0
    view_fps: float = 30.0
    latency_ms: float = 60.0
    jitter_ms: float = 5.0
    drop_rate: float = 0.0
    stop_after_s: float | None = None
    stop_camera: Literal["lf", "view", "both"] = "lf"
    down_for_s: float | None = None
    projector_missing: bool = False
    display: str | None = None
    host: str = "127.0.0.1"
    port: int = 0
    capture_spp: int | None = None
    view_spp: int | None = VIEW_SPP
    settle_s: float = 0.1
    camera_timeout_s: float = 30.0

    def __post_init__(self) -> None:
        problems = []
        for name in ("lf_fps", "view_fps"):
            if not getattr(self, name) > 0:
                problems.append(f"{name} must be > 0, got {getattr(self, name)}")
        for name in ("latency_ms", "jitter_ms", "settle_s"):
            if not getattr(self, name) >= 0:
                problems.append(f"{name} must be >= 0, got {getattr(self, name)}")
        if not 0 <= self.drop_rate < 1:
            problems.append(f"drop_rate must be in [0, 1), got {self.drop_rate}")
        if self.stop_camera not in ("lf", "view", "both"):
            problems.append(f"stop_camera must be lf, view or both, got {self.stop_camera!r}")
        if problems:
            raise ValueError("; ".join(problems))

    def timing(self, camera: str) -> CameraTiming:
        stops = self.stop_camera in (camera, "both")
        return CameraTiming(fps=self.lf_fps if camera == "lf" else self.view_fps, latency_s=self.latency_ms / 1e3,
                            jitter_s=self.jitter_ms / 1e3, drop_rate=self.drop_rate,
                            stop_after_s=self.stop_after_s if stops else None,
                            down_for_s=self.down_for_s if stops else None)


def manifest_path(rig_file: str | Path) -> Path:
    """The twin's manifest beside its rig file (``twin.toml`` -> ``twin.json``)."""
    return Path(rig_file).with_suffix(".json")


def _free_display() -> str:
    n = 90
    while Path(f"/tmp/.X11-unix/X{n}").exists() or Path(f"/tmp/.X{n}-lock").exists():
        n += 1
    return f":{n}"


class Twin:
    """A running device twin.

    Args:
        scene: the scene (its real objects are the twin's world; ``--quick`` already applied by the caller).
        rig_file: the rig file to write.
        options: :class:`TwinOptions`.
        scene_ref: how to load the scene again (``{"scene": path or name, "quick": bool}``), for the manifest.

    Raises:
        RuntimeError: no X display (Xvfb missing), or the display is smaller than the projector.
    """

    def __init__(self, scene, rig_file: str | Path, options: TwinOptions = TwinOptions(), *,
                 scene_ref: dict | None = None) -> None:
        from lftransfer.sim import hidden_world

        self.options = options
        self.rig_file = Path(rig_file)
        self._xvfb: subprocess.Popen | None = None
        self._closed = False
        world, truth = hidden_world(scene, options.truth_seed)
        self.world = TwinWorld(world, truth, options.truth_seed, capture_spp=options.capture_spp,
                               view_spp=options.view_spp)
        info = self.world.info
        try:
            if options.projector_missing:
                self.display = _free_display()
            elif options.display is None:
                self.display, self._xvfb = start_xvfb(*info.projector)
            else:
                self.display = options.display
            self.screen = ProjectorScreen(self.display, info.projector, info.projector_bits,
                                          missing=options.projector_missing)
            # the LF camera's exposure, in ms like the rig file's exposure of a camera (relative: 1 = nominal)
            self.lf_exposure_base = 1000.0 * float(scene.rig.exposure)
            self._lf_exposure = self.lf_exposure_base
            black = info.black()
            peak = float(np.max(self.world.radiance("view", black)))
            self.view_radiance_scale = VIEW_HEADROOM * peak if peak > 0 else 1.0
            self._view_levels = np.float32(65535.0 / self.view_radiance_scale)

            def state(t: float):
                key, image = self.screen.at(t)
                return (self.world.epoch, key), image

            self.cameras = {
                "lf": TwinCamera("lf", options.timing("lf"), state, lambda im: self.world.radiance("lf", im),
                                 self._lf_frame, seed=options.truth_seed or 0),
                "view": TwinCamera("view", options.timing("view"), state, lambda im: self.world.radiance("view", im),
                                   self._view_frame, seed=options.truth_seed or 0),
            }
            self.server = TwinServer(self.cameras, {"lf": (lambda: self._lf_exposure, self._set_lf_exposure)},
                                     self.world.arrange, self.status, options.host, options.port)
            self.started = time.monotonic()
            self.server.start()
            for cam in self.cameras.values():
                cam.start(self.started)
            self._write(scene_ref or {"scene": str(scene.source) if scene.source else None, "quick": False})
        except BaseException:
            self.close()
            raise

    # -- frames ---------------------------------------------------------------------------------------------
    def _lf_frame(self, radiance: np.ndarray) -> np.ndarray:
        scale = np.float32(self._lf_exposure / self.lf_exposure_base)
        return planar(self.world.expose_lf(radiance * scale if scale != 1 else radiance))

    def _view_frame(self, radiance: np.ndarray) -> np.ndarray:
        codes = np.clip(np.rint(radiance * self._view_levels), 0, 65535).astype(np.uint16)
        return planar(codes)

    def _set_lf_exposure(self, value: float) -> float:
        self._lf_exposure = float(value)
        return self._lf_exposure

    # -- files ----------------------------------------------------------------------------------------------
    def rig_text(self) -> str:
        """The rig file a ``HardwareRig`` opens to drive this twin."""
        info, o, url = self.world.info, self.options, self.server.url
        (lw, lh), (vw, vh), (pw, ph) = info.lf_camera, info.view, info.projector
        return f"""# Rig file of a device twin, written by `lft twin serve` (lftransfer.sim.twin); see example_rig.toml
# for every field. The cameras are network streams (NUT/FFV1 over HTTP, opened by OpenCV's VideoCapture).
# Their 16-bit colour frames travel as three stacked GRAY16LE planes (planar = true): OpenCV's FFmpeg reader
# returns 16 bits only for grey frames. Each frame carries its camera timestamp (timestamps = "stream").
# The twin's manifest (scene, truth seed) is {manifest_path(self.rig_file).name}.

[lf_camera]
source = "{url}/lf"
control = "{url}/lf/control"
width = {lw}
height = {lh}
bits = {info.lf_camera_bits}
planar = true
frames = 1
timeout_s = {o.camera_timeout_s}
timestamps = "stream"

[view_camera]
source = "{url}/view"
width = {vw}
height = {vh}
bits = 16
planar = true
frames = 1
timeout_s = {o.camera_timeout_s}
timestamps = "stream"
response_gamma = 1.0
radiance_scale = {self.view_radiance_scale!r}

[projector]
display = 0
x_display = "{self.display}"
width = {pw}
height = {ph}
bits = {info.projector_bits}
# not measured: `lft calibrate latency` measures the delay and writes it here
settle_s = {o.settle_s}
drop_frames = 0
stale_check = true
timeout_s = 10.0

[operator]
kind = "http"
url = "{url}/operator"
timeout_s = 600.0
"""

    def _write(self, scene_ref: dict) -> None:
        self.rig_file.parent.mkdir(parents=True, exist_ok=True)
        write_text(self.rig_file, self.rig_text())
        manifest = {"format": "lftransfer-twin", "version": 1, **scene_ref, "truth_seed": self.options.truth_seed,
                    "rig_file": str(self.rig_file.resolve()), "url": self.server.url, "display": self.display,
                    "pid": os.getpid(), "view_radiance_scale": self.view_radiance_scale,
                    "lf_exposure_base": self.lf_exposure_base, "options": asdict(self.options)}
        write_text(manifest_path(self.rig_file), json.dumps(manifest, indent=2) + "\n")

    # -- state ----------------------------------------------------------------------------------------------
    def status(self) -> dict:
        """What the twin has done so far (JSON)."""
        up = time.monotonic() - self.started
        return {
            "uptime_s": round(up, 3), "epoch": self.world.epoch, "setup": self.world.setup.kind,
            "screen_changes": self.screen.changes, "screen_error": self.screen.error,
            "renders": dict(self.world.renders), "render_s": {k: round(v, 3) for k, v in self.world.render_s.items()},
            "lf_exposure": self._lf_exposure,
            "cameras": {name: {"published": c.published, "dropped": c.dropped, "rerendered": c.rerendered, "missed": c.missed, "overrun": c.overrun,
                               "clients": c.clients, "down": c.down, "fps_set": c.timing.fps,
                               "fps_delivered": round(c.published / up, 2) if up > 0 else None}
                        for name, c in self.cameras.items()},
        }

    def wait(self, stop: threading.Event | None = None) -> None:
        """Serve until ``stop`` is set (or forever)."""
        (stop or threading.Event()).wait()

    def close(self) -> None:
        """Stop the cameras, the server and the twin's own Xvfb (idempotent)."""
        if self._closed:
            return
        self._closed = True
        for cam in getattr(self, "cameras", {}).values():
            cam.stop()
        if hasattr(self, "server"):
            self.server.close()
        if hasattr(self, "screen"):
            self.screen.close()
        if self._xvfb is not None:
            self._xvfb.terminate()
            try:
                self._xvfb.wait(timeout=5)
            except subprocess.TimeoutExpired:
                self._xvfb.kill()
        self.world.close()

    def __enter__(self) -> "Twin":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

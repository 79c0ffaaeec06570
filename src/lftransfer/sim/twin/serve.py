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

    A scene of several light field interfaces gets every interface's devices: one view camera (``/view``), and per
    interface an LF camera (``/lf`` for the first, ``/lf/NAME`` for the others, each with its exposure control),
    a projector (side by side on one X display's monitor: each rig file's ``projector.x``) and an operator
    endpoint (``/operator``, ``/operator/NAME``); and a rig file
    per interface (``RIG.toml`` for the first, ``RIG_NAME.toml`` for the others, which leave the view camera out:
    :func:`~lftransfer.rig.hardware.open_interfaces`), all given to ``--rig hardware:RIG.toml,RIG_NAME.toml``.

    Args:
        scene: the scene (its real objects are the twin's world; ``--quick`` already applied by the caller).
        rig_file: the rig file to write (the first interface's).
        options: :class:`TwinOptions`.
        scene_ref: how to load the scene again (``{"scene": path or name, "quick": bool}``), for the manifest.

    Raises:
        RuntimeError: no X display (Xvfb missing), or the display is smaller than the projector(s).
    """

    def __init__(self, scene, rig_file: str | Path, options: TwinOptions = TwinOptions(), *,
                 scene_ref: dict | None = None) -> None:
        from lftransfer.scenes.interfaces import interface_names
        from lftransfer.sim import hidden_world
        from lftransfer.sim.truth import true_interfaces

        self.options = options
        self.rig_file = Path(rig_file)
        self._xvfbs: list[subprocess.Popen] = []
        self._closed = False
        self.names = interface_names(scene.interfaces) if scene.interfaces else [""]
        world, truth = hidden_world(scene, options.truth_seed)
        truths = true_interfaces(scene, options.truth_seed) if scene.interfaces else None
        self.world = TwinWorld(world, truth, options.truth_seed, capture_spp=options.capture_spp,
                               view_spp=options.view_spp, truths=truths)
        try:
            # one X display, its monitor showing the projectors side by side (one process drives one X display)
            sizes = [info.projector for info in self.world.infos]
            self.origins = [(sum(w for w, _ in sizes[:i]), 0) for i in range(len(sizes))]
            if options.projector_missing:
                self.display = _free_display()
            elif options.display is None:
                self.display, xvfb = start_xvfb(sum(w for w, _ in sizes), max(h for _, h in sizes))
                self._xvfbs.append(xvfb)
            else:
                self.display = options.display
            self.screens = [ProjectorScreen(self.display, info.projector, info.projector_bits,
                                            missing=options.projector_missing, origin=origin)
                            for info, origin in zip(self.world.infos, self.origins)]
            # each LF camera's exposure, in ms like the rig file's exposure of a camera (relative: 1 = nominal)
            self.lf_exposure_base = 1000.0 * float(scene.rig.exposure)
            self._lf_exposure = [self.lf_exposure_base] * len(self.names)
            peak = float(np.max(self.world.radiance("view", [info.black() for info in self.world.infos])))
            self.view_radiance_scale = VIEW_HEADROOM * peak if peak > 0 else 1.0
            self._view_levels = np.float32(65535.0 / self.view_radiance_scale)
            self.cameras = self._cameras()
            exposure = {self.lf_path(i): (lambda i=i: self._lf_exposure[i], lambda v, i=i: self._set_lf_exposure(v, i))
                        for i in range(len(self.names))}
            arrange = {self.operator_path(i): lambda request, i=i: self.world.arrange(request, i)
                       for i in range(len(self.names))}
            self.server = TwinServer(self.cameras, exposure, arrange, self.status, options.host, options.port)
            self.started = time.monotonic()
            self.server.start()
            for cam in self.cameras.values():
                cam.start(self.started)
            self._write(scene_ref or {"scene": str(scene.source) if scene.source else None, "quick": False})
        except BaseException:
            self.close()
            raise

    def lf_path(self, i: int) -> str:
        """Interface ``i``'s LF camera stream (``lf``, ``lf/NAME``)."""
        return "lf" if i == 0 else f"lf/{self.names[i]}"

    def operator_path(self, i: int) -> str:
        """Interface ``i``'s operator endpoint (``operator``, ``operator/NAME``)."""
        return "operator" if i == 0 else f"operator/{self.names[i]}"

    @property
    def rig_files(self) -> list[Path]:
        """Every interface's rig file, in the scene's order (``--rig hardware:`` joins them with commas)."""
        stem = self.rig_file.stem
        return [self.rig_file, *(self.rig_file.with_name(f"{stem}_{name}.toml") for name in self.names[1:])]

    def _cameras(self) -> dict[str, TwinCamera]:
        """The view camera and each interface's LF camera, by stream path; each frame made from what every
        projector showed at its moment."""
        def state(t: float):
            shown = [screen.at(t) for screen in self.screens]
            return (self.world.epoch, tuple(key for key, _ in shown)), tuple(image for _, image in shown)

        seed = self.options.truth_seed or 0
        cameras = {"view": TwinCamera("view", self.options.timing("view"), state,
                                      lambda images: self.world.radiance("view", images), self._view_frame,
                                      seed=seed)}
        for i in range(len(self.names)):
            path = self.lf_path(i)
            cameras[path] = TwinCamera(path, self.options.timing("lf"), state,
                                       lambda images, i=i: self.world.radiance(f"lf{i}", images),
                                       lambda radiance, i=i: self._lf_frame(radiance, i), seed=seed)
        return cameras

    # -- frames ---------------------------------------------------------------------------------------------
    def _lf_frame(self, radiance: np.ndarray, interface: int = 0) -> np.ndarray:
        scale = np.float32(self._lf_exposure[interface] / self.lf_exposure_base)
        return planar(self.world.expose_lf(radiance * scale if scale != 1 else radiance, interface))

    def _view_frame(self, radiance: np.ndarray) -> np.ndarray:
        codes = np.clip(np.rint(radiance * self._view_levels), 0, 65535).astype(np.uint16)
        return planar(codes)

    def _set_lf_exposure(self, value: float, interface: int = 0) -> float:
        self._lf_exposure[interface] = float(value)
        return self._lf_exposure[interface]

    # -- files ----------------------------------------------------------------------------------------------
    def rig_text(self, interface: int = 0) -> str:
        """The rig file a ``HardwareRig`` opens to drive this twin (interface ``interface``'s devices; a later
        interface's leaves the view camera, the first's, out)."""
        info, o, url = self.world.infos[interface], self.options, self.server.url
        (lw, lh), (vw, vh), (pw, ph) = info.lf_camera, info.view, info.projector
        lf, operator = self.lf_path(interface), self.operator_path(interface)
        several = len(self.names) > 1
        head = (f"# Rig file of a device twin, written by `lft twin serve` (lftransfer.sim.twin); see "
                f"example_rig.toml\n# for every field. The cameras are network streams (NUT/FFV1 over HTTP, opened "
                f"by OpenCV's VideoCapture).\n# Their 16-bit colour frames travel as three stacked GRAY16LE planes "
                f"(planar = true): OpenCV's FFmpeg reader\n# returns 16 bits only for grey frames. Each frame carries "
                f"its camera timestamp (timestamps = \"stream\").\n# The twin's manifest (scene, truth seed) is "
                f"{manifest_path(self.rig_file).name}.\n")
        if several:
            head += (f"# Light field interface {self.names[interface]!r} ({interface + 1} of {len(self.names)}): "
                     f"--rig hardware:{','.join(p.name for p in self.rig_files)}\n")
        x, y = self.origins[interface]
        region = f"# the projectors side by side on the X display's monitor\nx = {x}\ny = {y}\n" if several else ""
        view = "" if interface else f"""
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
"""
        return head + f"""
[lf_camera]
source = "{url}/{lf}"
control = "{url}/{lf}/control"
width = {lw}
height = {lh}
bits = {info.lf_camera_bits}
planar = true
frames = 1
timeout_s = {o.camera_timeout_s}
timestamps = "stream"
{view}
[projector]
display = 0
x_display = "{self.display}"
width = {pw}
height = {ph}
{region}bits = {info.projector_bits}
# not measured: `lft calibrate latency` measures the delay and writes it here
settle_s = {o.settle_s}
drop_frames = 0
stale_check = true
timeout_s = 10.0

[operator]
kind = "http"
url = "{url}/{operator}"
timeout_s = 600.0
"""

    def _write(self, scene_ref: dict) -> None:
        self.rig_file.parent.mkdir(parents=True, exist_ok=True)
        for i, path in enumerate(self.rig_files):
            write_text(path, self.rig_text(i))
        manifest = {"format": "lftransfer-twin", "version": 1, **scene_ref, "truth_seed": self.options.truth_seed,
                    "rig_file": str(self.rig_file.resolve()), "url": self.server.url, "display": self.display,
                    "pid": os.getpid(), "view_radiance_scale": self.view_radiance_scale,
                    "lf_exposure_base": self.lf_exposure_base, "options": asdict(self.options)}
        if len(self.names) > 1:
            manifest.update(interfaces=self.names, rig_files=[str(p.resolve()) for p in self.rig_files])
        write_text(manifest_path(self.rig_file), json.dumps(manifest, indent=2) + "\n")

    # -- state ----------------------------------------------------------------------------------------------
    def status(self) -> dict:
        """What the twin has done so far (JSON)."""
        up = time.monotonic() - self.started
        return {
            "uptime_s": round(up, 3), "epoch": self.world.epoch, "setup": self.world.setup.kind,
            "screen_changes": sum(s.changes for s in self.screens),
            "screen_error": next((s.error for s in self.screens if s.error), None),
            "renders": dict(self.world.renders), "render_s": {k: round(v, 3) for k, v in self.world.render_s.items()},
            "lf_exposure": self._lf_exposure[0] if len(self.names) == 1 else self._lf_exposure,
            "cameras": {name: {"published": c.published, "dropped": c.dropped, "rerendered": c.rerendered, "missed": c.missed, "overrun": c.overrun,
                               "clients": c.clients, "down": c.down, "fps_set": c.timing.fps,
                               "fps_delivered": round(c.published / up, 2) if up > 0 else None}
                        for name, c in self.cameras.items()},
        }

    def wait(self, stop: threading.Event | None = None) -> None:
        """Serve until ``stop`` is set (or forever)."""
        (stop or threading.Event()).wait()

    def close(self) -> None:
        """Stop the cameras, the server and the twin's own Xvfbs (idempotent)."""
        if self._closed:
            return
        self._closed = True
        for cam in getattr(self, "cameras", {}).values():
            cam.stop()
        if hasattr(self, "server"):
            self.server.close()
        for screen in getattr(self, "screens", []):
            screen.close()
        for xvfb in self._xvfbs:
            xvfb.terminate()
            try:
                xvfb.wait(timeout=5)
            except subprocess.TimeoutExpired:
                xvfb.kill()
        self.world.close()

    def __enter__(self) -> "Twin":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

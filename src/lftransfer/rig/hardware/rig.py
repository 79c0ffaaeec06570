"""The physical rig: the :class:`~lftransfer.rig.base.Rig` protocol over two cameras and a projector window.

:class:`HardwareRig` opens the devices a rig file names (:mod:`.config`): the projector window
(:class:`~.projector.ProjectorWindow`, black at first), the LF camera and the view camera (:mod:`.camera`).

- :meth:`HardwareRig.setup` asks the operator (:mod:`.operator`): by default a person, through the ``operator``
  callback that gets the set-up's :meth:`prompt` text and returns once it is done (the CLI prints the prompt and
  waits for Enter); or the endpoint the rig file's ``[operator]`` table names (an HTTP URL or a command: a
  motorised stage, the device twin), which gets the typed set-up itself. The rig remembers the set-up and asks
  again only when a different one is requested; it starts in :class:`~lftransfer.rig.requests.RealScene`, as the
  protocol says. Without a callback, a set-up change for a person raises RigError ("needs an operator").
- :meth:`HardwareRig.project` shows the image. Frames that arrive before the swap + ``projector.settle_s`` are
  stale: cameras read continuously (network streams) skip them by their arrival time, and for the others the rig
  sleeps ``settle_s`` and drops ``projector.drop_frames`` frames. The same holds after a set-up or an exposure
  change.
- Stale check (``projector.stale_check``, cameras read continuously): after a change, the first frames are
  compared; one that still changed after ``settle_s`` is dropped, the capture waits for the image to hold still,
  and :attr:`HardwareRig.stale_captures` counts it (a warning names the camera, the step and the rig file's
  ``settle_s``). A settle time set too low is thus detected rather than averaged into captures.
- :meth:`HardwareRig.capture_lf` averages max(request.frames, lf_camera.frames) fresh frames and rounds them to
  uint16 codes; an exposure scale other than 1 sets the camera's exposure to base * scale (RigError where the
  camera does not allow it).
- :meth:`HardwareRig.capture_view` linearises every frame with the rig file's response,
  radiance = radiance_scale * (code / (2^bits - 1)) ^ response_gamma, and averages.

Every device fault is a :class:`~lftransfer.rig.base.RigError` naming the device and the step, e.g.
``"LF camera (/dev/video2): no frame within 5 s during capture_lf after projecting; ..."``.
"""

from __future__ import annotations

import logging
import time
from pathlib import Path
from typing import Callable

import numpy as np

from lftransfer.rig.base import RigError
from lftransfer.rig.hardware.camera import Camera
from lftransfer.rig.hardware.cameras import open_camera
from lftransfer.rig.hardware.config import HardwareRigConfig, load_rig_file
from lftransfer.rig.hardware.operator import arranger
from lftransfer.rig.hardware.projector import ProjectorWindow
from lftransfer.rig.requests import (SETUPS, LFCapture, LFFrame, RealScene, RigInfo, Setup, ViewCapture,
                                     ViewFrame)

__all__ = ["HardwareRig", "Operator", "no_operator", "open_interfaces"]

_log = logging.getLogger(__name__)

Operator = Callable[[str], None]
"""The operator callback: gets a set-up prompt, returns once it is done (raises to abort the run)."""


def no_operator(prompt: str) -> None:
    """The default operator callback: there is none, so a set-up change is an error.

    Args:
        prompt: what the operator would have been asked to do.

    Raises:
        RigError: always.
    """
    raise RigError(f"this step needs an operator at the rig (no operator callback was given): {prompt}")


class HardwareRig:
    """A physical light field transfer rig (:class:`~lftransfer.rig.base.Rig`).

    Args:
        config: the rig file (a :class:`~.config.HardwareRigConfig`, or a path to load).
        operator: called with a set-up's prompt; returns when the operator has done it. None:
            :func:`no_operator` (set-up changes raise RigError).
        lf_camera, view_camera: open cameras to use instead of opening the rig file's (tests, or a caller that
            holds them already; they are closed with the rig).
        projector: an open projector window to use instead of opening one.
        sleep: how to wait ``settle_s`` (tests pass a no-op).
        shared_view: the rig of the scene's first light field interface, whose view camera (and its rig file's
            ``view_camera``) this one, another interface's, uses and leaves open (:func:`open_interfaces`).

    Raises:
        RigError: a device that cannot be opened (the ones already open are closed again).
        RigFileError: an invalid rig file (when ``config`` is a path).
    """

    def __init__(self, config: HardwareRigConfig | str | Path, operator: Operator | None = None, *,
                 lf_camera: Camera | None = None, view_camera: Camera | None = None,
                 projector: ProjectorWindow | None = None, sleep: Callable[[float], None] = time.sleep,
                 shared_view: "HardwareRig | None" = None) -> None:
        self.config = config if isinstance(config, HardwareRigConfig) else load_rig_file(config)
        if shared_view is not None:
            self.config = self.config.model_copy(update={"view_camera": shared_view.config.view_camera})
            view_camera = shared_view._view
        self._owns_view = shared_view is None
        self._peers: list[HardwareRig] = []       # the other interfaces' rigs of one scene (join)
        self._operator: Operator = operator or no_operator
        self._arrange, self._endpoint = arranger(self.config.operator, lambda prompt: self._operator(prompt))
        self._sleep = sleep
        self._changed: dict[str, bool] = {"lf": False, "view": False}
        self.stale_captures = 0
        """Captures in which a frame taken ``settle_s`` after a change still changed (``settle_s`` too short)."""
        self._setup: Setup = RealScene()
        self._after = "after opening"
        self._closed = False
        self._projector: ProjectorWindow | None = projector
        self._lf: Camera | None = lf_camera
        self._view: Camera | None = view_camera
        self._info = self.config.info              # RigFileError without a view camera
        try:
            if self._projector is None:
                self._projector = ProjectorWindow(self.config.projector)
            if self._lf is None:
                self._lf = open_camera(self.config.lf_camera, "LF camera")
            if self._view is None:
                self._view = open_camera(self.config.view_camera, "view camera")
        except BaseException:
            self.close()
            raise
        if self._endpoint:                   # an endpoint can put the real scene in place itself
            try:
                self._arrange(RealScene())
            except BaseException:
                self.close()
                raise

    # -- Rig ---------------------------------------------------------------------------------------------------

    @property
    def info(self) -> RigInfo:
        """The devices' sizes and bit depths, from the rig file."""
        return self._info

    @property
    def current_setup(self) -> Setup:
        """The set-up the operator was last asked for (RealScene at first)."""
        return self._setup

    def _check_open(self, step: str) -> None:
        if self._closed:
            raise RigError(f"hardware rig: closed ({step})")

    def setup(self, request: Setup) -> None:
        """Have the operator arrange ``request``; nothing happens when it is the current set-up.

        Args:
            request: one of the set-ups of :mod:`lftransfer.rig.requests`.

        Raises:
            TypeError: ``request`` is not a set-up.
            RigError: no operator callback, or the callback raised it (the set-up is then not remembered).
        """
        if not isinstance(request, tuple(SETUPS.values())):
            raise TypeError(f"setup needs one of {sorted(SETUPS)}, got {type(request).__name__}")
        self._check_open(f"setup {request.kind}")
        if request == self._setup or (isinstance(request, RealScene) and isinstance(self._setup, RealScene)
                                      and not self._endpoint):
            self._setup = request            # a later moment of the real scene: its objects move by themselves
            return
        _log.info("set-up: %s", request.kind)
        self._arrange(request)
        self._setup = request
        self._after = f"after the set-up {request.kind}"
        self._change(time.monotonic())

    def project(self, image: np.ndarray) -> None:
        """Show ``image``; frames that arrive before the swap + ``settle_s`` are stale from now on (cameras read
        continuously skip them; for the others the rig sleeps until then).

        Args:
            image: (H, W, 3) uint8 for an 8-bit projector, else uint16 codes.

        Raises:
            ValueError: wrong shape or dtype (:meth:`RigInfo.check_projector_image`).
            RigError: the projector window fails or does not answer.
        """
        image = self._info.check_projector_image(image)
        self._check_open("project")
        assert self._projector is not None
        shown = self._projector.show(image, step="project")
        self._after = "after projecting"
        self._change(shown if shown is not None else time.monotonic())

    def join(self, rigs: list["HardwareRig"]) -> None:
        """Share one world with the rigs of the scene's other light field interfaces (``rigs``, this one among them):
        what this projector or this set-up changes, every interface's cameras see, so their frames before the change
        has settled are stale too."""
        self._peers = [r for r in rigs if r is not self]

    def _change(self, at: float) -> None:
        """What the cameras see changed at monotonic time ``at``: frames before ``at + settle_s`` are stale (on every
        joined interface's cameras too)."""
        settle = self.config.projector.settle_s
        cameras = []
        for rig in (self, *self._peers):
            cameras += [c for c in (rig._lf, rig._view) if c is not None and all(c is not k for k in cameras)]
            rig._changed = {"lf": True, "view": True}
        for cam in cameras:
            cam.mark_change(at + settle)
        if any(not cam.continuous for cam in cameras):
            self._sleep(max(0.0, at + settle - time.monotonic()))

    def _grab(self, camera: Camera, which: str, frames: int, step: str,
              transform: Callable[[np.ndarray], np.ndarray] | None = None) -> np.ndarray:
        """The mean of ``frames`` fresh frames; after a change, on a camera read continuously, the first frames are
        checked for staleness first (:meth:`_fresh_start`)."""
        drop = self.config.projector.drop_frames
        if not (camera.continuous and self.config.projector.stale_check and self._changed[which]):
            return camera.grab(frames, drop=drop, step=step, transform=transform)
        self._changed[which] = False
        for _ in range(drop):
            camera.read_frame(step)
        used = self._fresh_start(camera, step)
        while len(used) < frames:
            used.append(camera.read_frame(step)[0])
        used = used[:frames]
        if transform is not None:
            used = [np.asarray(transform(f), np.float32) for f in used]
        return (np.sum(np.asarray(used, np.float64), axis=0) / len(used)).astype(np.float32)

    STALE_RATIO = 3.0               # a step this many times the frame-to-frame noise is a change
    STALE_TOLERANCE = 2e-4          # ... and larger than this fraction of full scale (mean over 8 x 8 blocks)
    STALE_WINDOW = 4                # frames that must hold still (a change up to 3 frames late is caught)
    STALE_MAX_FRAMES = 8            # frames waited for the image to hold still

    def _fresh_start(self, camera: Camera, step: str) -> list[np.ndarray]:
        """Frames from the first one that no longer changes. Of :attr:`STALE_WINDOW` frames in a row, the steps
        between neighbours must all be noise: a step well above the smallest one (:attr:`STALE_RATIO`) is a change
        that arrived after ``settle_s``, and the frames before it are stale. They are dropped (counted in
        :attr:`stale_captures` and logged once per capture), never averaged; the last two frames of the still
        window start the capture."""
        levels = float(camera.config.levels)

        def small(frame: np.ndarray) -> np.ndarray:
            h, w = (frame.shape[0] // 8) * 8, (frame.shape[1] // 8) * 8
            if not (h and w):
                return frame
            return frame[:h, :w].reshape(h // 8, 8, w // 8, 8, -1).mean(axis=(1, 3))

        frames = [camera.read_frame(step)[0] for _ in range(self.STALE_WINDOW)]
        seen = [small(f) for f in frames]
        stale = 0
        while True:
            steps = [float(np.mean(np.abs(a - b))) / levels for a, b in zip(seen[-self.STALE_WINDOW:-1],
                                                                            seen[-self.STALE_WINDOW + 1:])]
            if not max(steps) > self.STALE_RATIO * min(steps) + self.STALE_TOLERANCE:
                break
            stale += 1
            if stale >= self.STALE_MAX_FRAMES:
                _log.warning("%s: the image kept changing for %d frames %s (%s); going on with the last "
                             "frames", camera.label, stale, self._after, step)
                break
            frames.append(camera.read_frame(step)[0])
            seen.append(small(frames[-1]))
        if stale:
            self.stale_captures += 1
            _log.warning("%s: a change arrived up to %d frame(s) later than projector.settle_s = %.3f s of the rig "
                         "file %s (%s); the frames before it were dropped, not averaged. Run `lft calibrate "
                         "latency` to measure the delay.", camera.label, stale, self.config.projector.settle_s,
                         self._after, step)
        return frames[-2:]

    def capture_lf(self, request: LFCapture = LFCapture()) -> LFFrame:
        """LF camera image of the current state.

        Args:
            request: exposure scale and frames to average (at least the rig file's ``lf_camera.frames``).

        Returns:
            :class:`LFFrame`: (H, W, 3) uint16 codes of ``lf_camera.bits`` bits.

        Raises:
            RigError: no frame within ``timeout_s``, a wrong frame size, or an exposure scale the camera cannot
                be set to.
        """
        step = f"capture_lf {self._after}"
        self._check_open(step)
        assert self._lf is not None
        c = self.config.lf_camera
        if self._lf.set_exposure_scale(request.exposure_scale, step=step):
            self._lf.mark_change(time.monotonic() + self.config.projector.settle_s)
            self._changed["lf"] = True
        mean = self._grab(self._lf, "lf", max(request.frames, c.frames), step)
        codes = np.clip(np.round(mean), 0, c.levels).astype(np.uint16)
        return LFFrame(codes=codes, bits=c.bits, exposure_scale=request.exposure_scale)

    def capture_view(self, request: ViewCapture = ViewCapture()) -> ViewFrame:
        """View camera image of the current state, linear radiance.

        Args:
            request: frames to average; ``quality``, where given, is the least number of frames.

        Returns:
            :class:`ViewFrame`: (H, W, 3) float32 radiance, W m^-2 sr^-1.

        Raises:
            RigError: no frame within ``timeout_s`` or a wrong frame size.
        """
        step = f"capture_view {self._after}"
        self._check_open(step)
        assert self._view is not None
        c = self.config.view_camera
        frames = max(request.frames, request.quality or 1, c.frames)
        gamma = np.asarray(c.gamma_rgb, np.float32)
        inv_levels = np.float32(1.0 / c.levels)
        scale = np.float32(c.radiance_scale)

        def linear(codes: np.ndarray) -> np.ndarray:
            return scale * np.power(np.clip(codes * inv_levels, 0.0, 1.0), gamma)

        radiance = self._grab(self._view, "view", frames, step, transform=linear)
        return ViewFrame(radiance=radiance.astype(np.float32))

    def close(self) -> None:
        """Close the projector window and release the cameras (idempotent)."""
        if self._closed:
            return
        self._closed = True
        for device in (self._lf, self._view if self._owns_view else None, self._projector):
            if device is not None:
                try:
                    device.close()
                except Exception:  # noqa: BLE001  (close the others all the same)
                    _log.warning("closing %s failed", getattr(device, "label", device), exc_info=True)

    def __enter__(self) -> "HardwareRig":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def open_interfaces(configs: list[HardwareRigConfig | str | Path], operator: Operator | None = None
                    ) -> list[HardwareRig]:
    """The rigs of a scene's light field interfaces, one rig file each, in the scene's order: the first opens the
    view camera, the others use it (their rig files may leave ``[view_camera]`` out); each has its own LF camera,
    projector window and operator, and they are joined (:meth:`HardwareRig.join`). A device that cannot be opened
    closes the ones already open.

    Raises:
        RigError: a device that cannot be opened.
        RigFileError: an invalid rig file, or a first one without a view camera.
    """
    rigs: list[HardwareRig] = []
    try:
        for config in configs:
            rigs.append(HardwareRig(config, operator, shared_view=rigs[0] if rigs else None))
    except BaseException:
        for rig in reversed(rigs):
            rig.close()
        raise
    for rig in rigs:
        rig.join(rigs)
    return rigs

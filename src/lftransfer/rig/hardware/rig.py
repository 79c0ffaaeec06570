"""The physical rig: the :class:`~lftransfer.rig.base.Rig` protocol over two cameras and a projector window.

:class:`HardwareRig` opens the devices a rig file names (:mod:`.config`): the projector window
(:class:`~.projector.ProjectorWindow`, black at first), the LF camera and the view camera (:mod:`.camera`).

- :meth:`HardwareRig.setup` asks the operator: the ``operator`` callback gets the set-up's
  :meth:`prompt` text and returns once the operator has done it (the CLI prints the prompt and waits for Enter).
  The rig remembers the set-up and asks again only when a different one is requested; it starts in
  :class:`~lftransfer.rig.requests.RealScene`, as the protocol says (the operator starts a run with the real
  scene in place). Without a callback, a set-up change raises RigError ("needs an operator").
- :meth:`HardwareRig.project` shows the image and waits the rig file's ``projector.settle_s``.
- :meth:`HardwareRig.capture_lf` drops ``projector.drop_frames`` stale frames, averages
  max(request.frames, lf_camera.frames) frames and rounds them to uint16 codes; an exposure scale other than 1
  sets the camera's exposure to base * scale (RigError where the camera does not allow it).
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
from lftransfer.rig.hardware.camera import Camera, open_camera
from lftransfer.rig.hardware.config import HardwareRigConfig, load_rig_file
from lftransfer.rig.hardware.projector import ProjectorWindow
from lftransfer.rig.requests import (SETUPS, LFCapture, LFFrame, RealScene, RigInfo, Setup, ViewCapture,
                                     ViewFrame)

__all__ = ["HardwareRig", "Operator", "no_operator"]

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

    Raises:
        RigError: a device that cannot be opened (the ones already open are closed again).
        RigFileError: an invalid rig file (when ``config`` is a path).
    """

    def __init__(self, config: HardwareRigConfig | str | Path, operator: Operator | None = None, *,
                 lf_camera: Camera | None = None, view_camera: Camera | None = None,
                 projector: ProjectorWindow | None = None, sleep: Callable[[float], None] = time.sleep) -> None:
        self.config = config if isinstance(config, HardwareRigConfig) else load_rig_file(config)
        self._operator: Operator = operator or no_operator
        self._sleep = sleep
        self._setup: Setup = RealScene()
        self._after = "after opening"
        self._closed = False
        self._projector: ProjectorWindow | None = projector
        self._lf: Camera | None = lf_camera
        self._view: Camera | None = view_camera
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
        self._info = self.config.info

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
        if request == self._setup or (isinstance(request, RealScene) and isinstance(self._setup, RealScene)):
            self._setup = request            # a later moment of the real scene: its objects move by themselves
            return
        _log.info("set-up: %s", request.kind)
        self._operator(request.prompt())
        self._setup = request
        self._after = f"after the set-up {request.kind}"

    def project(self, image: np.ndarray) -> None:
        """Show ``image`` and wait the rig file's ``settle_s``.

        Args:
            image: (H, W, 3) uint8 for an 8-bit projector, else uint16 codes.

        Raises:
            ValueError: wrong shape or dtype (:meth:`RigInfo.check_projector_image`).
            RigError: the projector window fails or does not answer.
        """
        image = self._info.check_projector_image(image)
        self._check_open("project")
        assert self._projector is not None
        self._projector.show(image, step="project")
        self._sleep(self.config.projector.settle_s)
        self._after = "after projecting"

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
        self._lf.set_exposure_scale(request.exposure_scale, step=step)
        mean = self._lf.grab(max(request.frames, c.frames), drop=self.config.projector.drop_frames, step=step)
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

        radiance = self._view.grab(frames, drop=self.config.projector.drop_frames, step=step, transform=linear)
        return ViewFrame(radiance=radiance.astype(np.float32))

    def close(self) -> None:
        """Close the projector window and release the cameras (idempotent)."""
        if self._closed:
            return
        self._closed = True
        for device in (self._lf, self._view, self._projector):
            if device is not None:
                try:
                    device.close()
                except Exception:  # noqa: BLE001  (close the others all the same)
                    _log.warning("closing %s failed", getattr(device, "label", device), exc_info=True)

    def __enter__(self) -> "HardwareRig":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

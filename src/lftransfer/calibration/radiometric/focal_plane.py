"""The focal-plane diffuser captures that steps (a) to (c) of :mod:`lftransfer.calibration.radiometric` share."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lftransfer.rig.base import Rig
from lftransfer.rig.requests import LFCapture


@dataclass
class _FocalPlane:
    """The focal-plane diffuser captures: projector images of uniform or ramp codes, LF captures as normalised codes.

    Attributes:
        rig: the rig (its set-up is the :class:`~lftransfer.rig.requests.FocalPlaneDiffuser` while captured).
        shape: ``(H, W)`` of the projector, pixels.
        levels: the projector's full-scale code; ``dtype`` its images' dtype.
        camera_levels: the LF camera's full-scale code.
        captures: LF captures taken so far.
    """

    rig: Rig
    shape: tuple[int, int]
    levels: int
    dtype: np.dtype
    camera_levels: float
    captures: int = 0

    def capture(self, image: np.ndarray, e: float) -> np.ndarray:
        """Project ``image`` and capture at exposure scale ``e``: ``(H, W, 3) float32`` codes in [0, 1]."""
        self.captures += 1
        self.rig.project(image)
        codes = self.rig.capture_lf(LFCapture(exposure_scale=float(e))).codes
        return codes.astype(np.float32) / np.float32(self.camera_levels)

    def uniform(self, codes) -> np.ndarray:
        """``(H, W, 3)`` projector image of the same codes (3,) everywhere."""
        prj_h, prj_w = self.shape
        return np.broadcast_to(np.asarray(codes, self.dtype), (prj_h, prj_w, 3)).copy()

"""The ``Rig`` protocol: the pipeline's only door to the real world."""

from __future__ import annotations

from typing import Protocol, runtime_checkable

import numpy as np


@runtime_checkable
class Rig(Protocol):
    """A light field transfer rig: a projector and an LF camera behind a lens array, and a view camera.

    Images cross this boundary as device integers (LF camera, projector) or as the view camera's linear
    radiance image.
    """

    @property
    def projector_shape(self) -> tuple[int, int]:
        """(height, width) of the projector image."""

    def project(self, image: np.ndarray) -> None:
        """Show ``image`` ((H, W, 3) uint8 for an 8-bit projector) until the next call."""

    def capture_lf(self) -> np.ndarray:
        """LF camera image, (H, W, 3) uint16 holding ``bits``-bit codes."""

    def capture_view(self) -> np.ndarray:
        """View camera image, (H, W, 3) float32 linear radiance (W m^-2 sr^-1)."""

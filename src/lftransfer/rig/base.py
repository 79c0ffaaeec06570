"""The ``Rig`` protocol: the pipeline's only door to the real world (docs/architecture.md, "The rig boundary").

The transfer, the live loop and every calibration step talk to a rig through these methods only, so the same
code runs on the simulated rig (``lftransfer.sim.SimRig``), a physical rig
(:class:`lftransfer.rig.hardware.HardwareRig`) or a recording (:class:`lftransfer.rig.replay.ReplayRig`).
Requests and answers are the dataclasses of :mod:`lftransfer.rig.requests`.

A rig is a small state machine: :meth:`Rig.setup` arranges what the array faces (the real scene, a collimator,
a diffuser, a board held by an operator) and :meth:`Rig.project` what the projector shows; both stay until the
next call. Captures see the current state.
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

import numpy as np

from lftransfer.rig.requests import LFCapture, LFFrame, RigInfo, Setup, ViewCapture, ViewFrame

__all__ = ["Rig", "RigError"]


class RigError(RuntimeError):
    """A device fault: names the device and the step (e.g. "LF camera (/dev/video2): no frame within 5.0 s
    while capturing the LF camera after projecting")."""


@runtime_checkable
class Rig(Protocol):
    """A light field transfer rig: a projector and an LF camera behind a lens array, and a view camera."""

    @property
    def info(self) -> RigInfo:
        """The devices' sizes and bit depths."""

    def setup(self, request: Setup) -> None:
        """Arrange what the array faces (:data:`~lftransfer.rig.requests.Setup`); a physical rig asks its
        operator and waits. The rig starts in :class:`~lftransfer.rig.requests.RealScene`."""

    def project(self, image: np.ndarray) -> None:
        """Show ``image`` ((H, W, 3) uint8 for an 8-bit projector, else uint16) until the next call."""

    def capture_lf(self, request: LFCapture = LFCapture()) -> LFFrame:
        """LF camera image of the current state (no stale frame: taken after the last set-up or projection)."""

    def capture_view(self, request: ViewCapture = ViewCapture()) -> ViewFrame:
        """View camera image of the current state, linear radiance."""

    def close(self) -> None:
        """Release the devices (idempotent)."""

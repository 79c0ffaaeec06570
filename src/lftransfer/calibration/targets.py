"""The accuracy targets of calibration, defined once (docs/calibration.md).

Each target bounds one error that :func:`lftransfer.sim.calibration_errors.calibration_errors` measures against a
simulated
rig's hidden truth. The calibration report marks each pass or fail, ``lft calibrate seeds`` tabulates the worst
seed against it, and the tests read the same bounds: nothing else defines them.

Example:
    >>> from lftransfer.calibration.targets import TARGETS, target
    >>> target("pose_rotation_deg").bound
    0.2
    >>> target("pose_rotation_deg").met(-0.15)
    True
"""

from __future__ import annotations

import math
from dataclasses import dataclass

__all__ = ["TARGETS", "Target", "target"]


@dataclass(frozen=True)
class Target:
    """An accuracy target.

    Attributes:
        key: the error's name in ``calibration_errors`` (and calibration_errors.json).
        bound: the largest |error| that passes, in the error's own unit.
        unit: that unit.
        what: what the error measures, in words.
    """

    key: str
    bound: float
    unit: str
    what: str

    def met(self, value: float) -> bool:
        """Whether ``value`` (an error; its sign does not matter) meets the target; NaN never does."""
        return math.isfinite(float(value)) and abs(float(value)) <= self.bound


TARGETS: tuple[Target, ...] = (
    Target("lenslet_centre_rms_px", 0.1, "LF camera px", "lenslet centres, RMS"),
    Target("projector_mapping_rms_px", 0.5, "projector px", "projector mapping, RMS"),
    Target("pose_position_rms_mm", 1.0, "mm", "global pose: lenslet positions in the world, RMS"),
    Target("pose_position_max_mm", 1.0, "mm", "global pose: lenslet positions in the world, worst lenslet"),
    Target("pose_rotation_deg", 0.2, "deg", "global pose: array orientation"),
    Target("camera_response_error", 0.01, "of full scale", "camera response curves, max"),
    Target("projector_response_error", 0.01, "of full scale", "projector response curves, max"),
    Target("exposure_rel_error", 0.01, "relative", "LF camera exposure"),
    Target("light_position_error_mm", 1.0, "mm", "point light position"),
)


def target(key: str) -> Target:
    """The target of the error ``key``.

    Raises:
        KeyError: no target bounds that error.
    """
    for t in TARGETS:
        if t.key == key:
            return t
    raise KeyError(f"no calibration target for {key!r}; targets: {', '.join(t.key for t in TARGETS)}")

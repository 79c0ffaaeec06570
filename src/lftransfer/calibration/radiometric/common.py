"""What every step of the radiometric calibration shares: its error, the board it uses, code thresholds.

See :mod:`lftransfer.calibration.radiometric` for the procedure.
"""

from __future__ import annotations

import math
from typing import Callable

from lftransfer.calibration.pose import CHART

Progress = Callable[[str], None]

BOARD_DISTANCES = (0.2, 0.15, 0.12, 0.1)    # metres in front of the array centre, the first the view sees well
BOARD_SIZE = (0.2, 0.2)
BOARD_ALBEDO = 0.8
BOARD_CHART = CHART               # its printed chessboard (the pose boards' own), which tells where it really stands

_DARK, _BRIGHT = 0.04, 0.95         # usable normalised camera codes for the response fit
_SATURATED = 0.97


class RadiometryError(RuntimeError):
    """A radiometric calibration step could not be done (the message says which and why)."""


def _stride(h: int, w: int, target: int) -> int:
    return max(1, int(math.ceil(math.sqrt(h * w / target))))

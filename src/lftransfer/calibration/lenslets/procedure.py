"""The lenslet calibration from one image: detection by kind, the lattice fit, the centres as CSV.

See :mod:`lftransfer.calibration.lenslets` for the steps and the conventions.
"""

from __future__ import annotations

import numpy as np

from lftransfer.calibration.lenslets.common import NoSpotsError, _as_grey, _check_lattice, _check_shape
from lftransfer.calibration.lenslets.fit import LatticeFit
from lftransfer.calibration.lenslets.lattice import _fit_lattice
from lftransfer.calibration.lenslets.spots import _detect_spots
from lftransfer.calibration.lenslets.white import _detect_white, _looks_white
from lftransfer.imageio_utils import write_text

_KINDS = ("spots", "white")


def find_lenslet_centres(image: np.ndarray, lattice: str, *, expected_shape: tuple[int, int] | None = None,
                         kind: str = "spots") -> LatticeFit:
    """Find every lenslet's centre to sub-pixel accuracy and fit the lattice (see the module's docstring).

    Args:
        image: ``(H, W)`` grey image (float, any scale), or any array :func:`lftransfer.calibration.images.to_grey`
            takes (``uint8``/``uint16``, colour): bright spots on a dark background (``kind="spots"``) or a
            white image (``kind="white"``).
        lattice: ``"hex"`` or ``"rect"``.
        expected_shape: ``(rows, cols)`` of the lens array, if known: a fit spanning more rows or columns is an
            error, and for ``hex`` an odd top row (row 0 clipped off) is recognised and indexed as such.
        kind: ``"spots"`` (a collimated on-axis source: one small spot per lenslet) or ``"white"`` (a uniformly
            lit diffuser: one bright sub-image about a pitch wide per lenslet).

    Returns:
        The fit; ``centres`` holds only lenslets whose spot (white: sub-image, or half a pitch around the centre
        where sub-images touch) is wholly inside the image (missing ones are absent), and ``LatticeFit.kind``
        is ``kind``.

    Raises:
        ValueError: ``lattice`` is neither ``"hex"`` nor ``"rect"``, ``kind`` neither ``"spots"`` nor
            ``"white"``, or the image is not an image.
        NoSpotsError: no spots (sub-images), fewer than 4, or no lattice of that kind through them.
    """
    _check_lattice(lattice)
    if kind not in _KINDS:
        raise ValueError(f"kind must be 'spots' (collimated-source spot image) or 'white' (white image), "
                         f"got {kind!r}")
    if expected_shape is not None:
        _check_shape(expected_shape)
    img = _as_grey(image)
    if kind == "spots":
        try:
            points, sigma = _detect_spots(img)
        except NoSpotsError as exc:
            if _looks_white(img):
                raise NoSpotsError(f"{exc}; the image is mostly bright and periodic, like a white image: "
                                   "pass kind='white'") from None
            raise
    else:
        points, sigma = _detect_white(img, lattice)
    if len(points) < 4:
        what = "spot(s)" if kind == "spots" else "sub-image(s)"
        raise NoSpotsError(f"found {len(points)} lenslet {what}; at least 4 are needed to fit a lattice")
    return _fit_lattice(points, lattice, img.shape, sigma, expected_shape, kind)


def write_centres_csv(path, fit: LatticeFit) -> None:
    """Write the lenslet centres as CSV, atomically (temporary file in the same folder, then ``os.replace``).

    The header is ``x,y``; then one line per detected lenslet in row-major order of lattice index, pixel
    coordinates (origin at the centre of the top-left pixel) with 4 decimals.

    Args:
        path: destination file; its folder is created if missing.
        fit: the result of :func:`find_lenslet_centres`.
    """
    text = "x,y\n" + "".join(f"{x:.4f},{y:.4f}\n" for x, y in np.asarray(fit.centres, dtype=np.float64))
    write_text(path, text)

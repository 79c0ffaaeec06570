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
# A lens array's image fits its lattice model within a small fraction of the pitch; anything else is refused
# (see :func:`_refuse_poor_fit` for the measurements behind these two numbers).
_MAX_FIT_RMS_PITCH = 0.005     # largest RMS residual of the lattice fit, pitches ...
_MAX_FIT_RMS_FLOOR_PX = 0.1    # ... or pixels, whichever is larger


def find_lenslet_centres(image: np.ndarray, lattice: str, *, expected_shape: tuple[int, int] | None = None,
                         kind: str = "spots") -> LatticeFit:
    """Find every lenslet's centre to sub-pixel accuracy and fit the lattice (see the module's docstring).

    Args:
        image: ``(H, W)`` grey image (float, any scale), or any array :func:`lftransfer.imageio_utils.to_grey`
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
        NoSpotsError: no spots (sub-images), fewer than 4, or no lattice of that kind through them, or a lattice
            that fits them too poorly to be a lens array's (:func:`_refuse_poor_fit`; e.g. a photograph of a
            scene).
    """
    fit = _find_lenslet_centres_unchecked(image, lattice, expected_shape=expected_shape, kind=kind)
    _refuse_poor_fit(fit)
    return fit


def _find_lenslet_centres_unchecked(image: np.ndarray, lattice: str, *,
                                    expected_shape: tuple[int, int] | None = None, kind: str = "spots") -> LatticeFit:
    """:func:`find_lenslet_centres` without the check of the fit's quality (same arguments, same fit)."""
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


def _refuse_poor_fit(fit: LatticeFit) -> None:
    """Refuse a lattice fit whose RMS residual is not a lens array's: one line that says what was measured.

    The limit is ``max(_MAX_FIT_RMS_PITCH * pitch, _MAX_FIT_RMS_FLOOR_PX)``: 0.5 % of the pitch, at least 0.1 px
    (the centroids' noise is in pixels; the residual of aberrated or distorted spots grows with the pitch).
    Measured (``tests/calibration/measure_lattice_rms.py --full``), RMS residual of the lattice model:

    * good images, at most 0.00086 pitch: the simulated rig (Fig. 4 scene, perturbed truth) at full resolution
      (2048 x 1536, pitch 157.4 px): on-axis collimator 0.0040 px, the 25 collimator tilts of the distortion
      sweep (tan up to 0.3) up to 0.132 px (0.00084 pitch; limit 0.79 px); at a quarter of it (pitch 39.4 px):
      0.0037 px and up to 0.034 px (0.00086 pitch; limit 0.20 px); the synthetic spot and white images of the
      tests (pitch 22 to 38 px, distorted, tilted, vignetted, noisy): 0.008 to 0.020 px (limit 0.10 to 0.19 px);
    * images that are none, at least 0.026 pitch: the simulated LF camera's photograph of the Fig. 4 real scene
      read as a white image (quarter resolution): 1.21 px at a fitted pitch of 45.7 px (0.027 pitch; limit
      0.23 px); synthetic spot and white images whose blobs are moved off the lattice at random by 0.02 pitch:
      0.81 to 0.82 px at 28 px (0.029 pitch; limit 0.14 px). (Photographs without blobs, such as the view
      camera's of the real scene or random textures, fail earlier: no spots, or no lattice symmetry.)

    The limit thus lies about 6 times above the worst good fit and 5 times below the best bad one.

    Raises:
        NoSpotsError: the RMS residual exceeds the limit.
    """
    limit = max(_MAX_FIT_RMS_PITCH * fit.pitch_px, _MAX_FIT_RMS_FLOOR_PX)
    if fit.rms_px <= limit:
        return
    what = "spots" if fit.kind == "spots" else "sub-images"
    rows, cols = fit.shape
    if fit.expected_shape is not None:
        er, ec = fit.expected_shape
        expected = f"of {er * ec} lenslets expected ({er} x {ec})"
    else:
        expected = f"of {rows * cols} nodes in the {rows} x {cols} lattice they span"
    raise NoSpotsError(
        f"poor lattice fit: {len(fit.centres)} {what} on a {fit.lattice} lattice ({expected}; {fit.rejected} more "
        f"off it), RMS residual {fit.rms_px:.3f} px = {100 * fit.rms_px / fit.pitch_px:.2f} % of the "
        f"{fit.pitch_px:.1f} px pitch, more than the {limit:.3f} px a lens array's image fits within: expected a "
        "spot image or a white image of the lens array: a collimated on-axis source through it (kind='spots') or "
        "an evenly lit diffuser in front of it (kind='white')")

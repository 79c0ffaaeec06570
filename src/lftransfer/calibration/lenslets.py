"""Lenslet centres from a spot image (collimated on-axis source) or a white image, and the lattice through them.

Two kinds of calibration image are understood (``kind=`` of :func:`find_lenslet_centres`):

* ``"spots"``: a collimated on-axis source seen through the lens array. Every lenslet focuses the plane wave
  into one small spot at the image of its optical centre (see the simulated rig's ``Collimator`` set-up);
  the spot's centroid is the lenslet's centre.
* ``"white"``: a uniformly lit diffuser in front of the array (the usual light-field camera calibration
  image). Every lenslet's sub-image is a bright blob about one pitch wide (the footprint of its aperture, a
  disk or hexagon with a soft, vignetted fall-off towards its edge), touching or nearly touching its
  neighbours, the whole image dimmer towards the corners (main-lens vignetting). The sub-image's centre of
  symmetry is the image of the chief ray through the lenslet's centre. For our rig, where the camera images
  the lenslets' focal plane telecentrically, that chief ray is parallel to the axis, so the white image's
  sub-image centres coincide with the on-axis collimated spots of a spot image (in a light-field camera
  whose main lens is not telecentric they are the spots of a source at the main lens' exit pupil instead).

:func:`find_lenslet_centres` finds those centres to a small fraction of a pixel and fits the lattice to them
(``lft calibrate lenslets IMAGE --lattice hex --out centres.csv``):

1. spots (``"spots"``):

   a. background: the median of 16 or 32 pixel blocks, interpolated, is subtracted (follows vignetting and an
      uneven dark background); later passes leave the bright pixels of the previous one out, so that dense
      spots do not raise it. Hot pixels (a single pixel far above its 3 x 3 median) are replaced by that
      median. The noise is measured on what is left, without the spots, on the lower half of the
      distribution (the upper half where the dark background was clipped at zero);
   b. detection: local maxima of the lightly smoothed image above 5 noise sigmas, above 10 % of the brightest
      spot within two pitches and above 5 % of the bright spots (95th percentile) anywhere (dim vignetted
      border spots are kept, noise maxima are not); spots whose centre lies within ``2.5 sigma`` (at least
      2 px) of the image border are dropped (clipped spots);
   c. sub-pixel centres: Gaussian-windowed centroid (the window's sigma is the spots' own, estimated from the
      brightest spots), iterated to its fixed point on the background-subtracted image, after subtracting
      each spot's local background (median of a ring around it);

2. sub-images (``"white"``):

   a. pitch: the nearest peak of the image's autocorrelation (central crop, high-passed, Hann-windowed);
   b. detection: the image is divided by its vignetting envelope (a Gaussian blur of about one pitch, which
      wipes out the lattice's period), smoothed with a Gaussian of a fifth of the pitch (each sub-image
      becomes one peak near its centre), and its local maxima (one per 0.7 pitch) that stand out from their
      surroundings (at least 30 % of the typical peak's contrast, where the envelope is above 10 % of its
      top) are the sub-images;
   c. sub-pixel centres: centroid of the image within a flat, centrally symmetric window (2 px soft edge),
      iterated to its fixed point: the sub-image's centre of symmetry. A first pass uses a disk of radius
      half the pitch. The main lens' vignetting tilts each sub-image (a bias of ``gradient * radius^2 / 4``,
      a few hundredths of a pixel, towards the image centre), so each sub-image's relative brightness gradient
      is measured from its neighbours' mean brightnesses (a plane fitted to those within 2.3 pitches) and
      divided out of its window in a second pass. That pass's window follows the distorted lattice: a disk of
      half the local pitch for sub-images apart from each other, or, for touching ones (whose radial profile
      does not fall to a dark gap within half a pitch), the sub-image's own lattice cell (hexagon or
      rectangle through the midpoints to its neighbours, 1 px in, symmetrised), so that no neighbour, nearer
      on one side than on the other where the pitch changes, reaches into it. Near the image border the window
      is cut by a disk that stays inside the image, down to the sub-image's extent. Sub-images darker than
      75 % of their neighbours (cut by the edge of the lit area) and those cut by the image border are
      dropped;

3. lattice (both kinds): pitch from nearest-neighbour distances, rotation from the neighbours' directions
   (modulo 60 deg for ``hex``, 90 deg for ``rect``). Integer indices are assigned by growing the lattice from
   the detection nearest the middle outwards: each unassigned detection within 2.2 pitches of assigned ones
   is predicted in lattice coordinates from up to four assigned neighbours through their local lattice
   Jacobians (local affine fits of the assigned nodes within 2.6 pitches), and takes the nearest node if all
   predictions agree on it (within 0.3 of a pitch for the mean, 0.4 for each) and no detection holds it
   yet. The growth follows any smooth distortion (a main lens' barrel or pincushion distortion of several
   pitches at the corners), which a global homography does not;
4. lattice model: a homography from the ideal lattice to undistorted pixels, followed by radial distortion
   about a fitted centre,

   ``p = c + (q - c) (1 + k1 rho^2 + k2 rho^4)``, ``q = H (u, v, 1)``, ``rho = |q - c| / s``,

   with ``s`` the image's half-diagonal (``c`` is held near the image centre by a weak prior, which only
   matters while the distortion is too weak to locate it). It is fitted by least squares to the grown
   detections (Levenberg-Marquardt, from the least-squares homography); detections a quarter pitch or more
   off it, or farther from it than 8 robust sigmas of the residuals and 0.2 px (a disturbed spot or a cut
   sub-image), are dropped, refitting until none is; detections the growth did not reach are assigned
   through the model's inverse, and the model is refitted to all. The radial terms are kept only if they
   explain significantly more than noise (F-test of the two fits, F > 10, and the RMS down by 2 % or more);
   otherwise ``k1 = k2 = 0`` and the model is the least-squares homography, as for an undistorted image.
   ``LatticeFit.rms_px`` is the residual of that model; ``LatticeFit.homography_rms_px`` that of the best
   homography alone, for comparison.

Conventions:

* pixel coordinates ``(x, y)`` = (col, row), origin at the centre of the top-left pixel, y down;
* lattice indices ``(row, col)``: the rows run along the lattice direction closest to the image x axis, row
  indices grow downwards in the image and column indices to the right; the top detected row is row 0 and
  the leftmost detected lenslet is in column 0;
* ideal lattice coordinates (unit pitch) of index ``(r, c)``: ``u = c + (r % 2) / 2`` for ``hex`` (odd rows
  shifted by half a pitch towards +x, like ``LensArray``), ``u = c`` for ``rect``; ``v = r sqrt(3) / 2`` for
  ``hex``, ``v = r`` for ``rect``. For ``hex``, column 0 is the leftmost node over all rows in that
  convention: if the top detected row is shifted right of the row below it, its first lenslet is in column 1
  and the row below starts at column 0 (then the top detected row is an odd row of the physical array, e.g.
  row 0 clipped off; pass ``expected_shape`` to have the indices match the array's in that case).
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field
from typing import NamedTuple

import cv2
import numpy as np
from scipy.ndimage import median_filter
from scipy.optimize import least_squares
from scipy.spatial import cKDTree

from lftransfer.imageio_utils import write_text

__all__ = ["LatticeFit", "NoSpotsError", "find_lenslet_centres", "lattice_coordinates", "write_centres_csv"]

_SQRT3_2 = math.sqrt(3.0) / 2.0
_ROW_STEP = {"hex": _SQRT3_2, "rect": 1.0}
_SNR = 5.0                 # detection threshold, noise sigmas of the smoothed image
_REL = 0.10                # ... and fraction of the brightest spot within two pitches
_REL_GLOBAL = 0.05         # ... and fraction of the bright spots anywhere (noise maxima far from the array)
_HOT = 0.8                 # (pixel - 3x3 median) / pixel above this: a hot pixel (a spot of sigma <~ 0.55 px)
_MAX_RESIDUAL = 0.25       # a detection farther than this (lattice pitches) from its node is not a lenslet
_KINDS = ("spots", "white")
_OUTLIER_SIGMAS = 8.0      # a detection farther than this many robust sigmas off the lattice model is dropped
_OUTLIER_FLOOR_PX = 0.2    # ... if also farther than this (pixels)
_GROW_REACH = 2.2          # growth: detections this close (pitches) to assigned ones are predicted from them
_GROW_TOL = 0.3            # ... and take the nearest node if their mean prediction is this close (pitches)
_GROW_AGREE = 0.4          # ... and every single neighbour's prediction this close
_JAC_REACH = 2.6           # local lattice Jacobian: affine fit of the assigned nodes within this (pitches)
_CENTRE_PRIOR_PX = 2.0     # prior on the distortion centre: residual (px) per half-diagonal off the image centre
_F_RADIAL = 10.0           # radial terms kept if F of (homography vs homography + radial) exceeds this
_WHITE_SMOOTH = 0.2        # white images: detection smoothing sigma, pitches
_WHITE_WINDOW = 0.5        # ... centroid window radius, pitches
_WHITE_BRIGHT = 0.3        # ... a sub-image's brightness: mean within this radius (pitches) of its centre
_CELL_DISK = 0.72          # ... second pass: the cell window is cut by a disk of this radius (pitches; beyond the
                           #     corners of hex and rect cells) or of the distance to the image border
_WHITE_REL = 0.3           # ... a peak's contrast at least this fraction of the typical peak's
_WHITE_ENVELOPE = 0.1      # ... where the vignetting envelope is at least this fraction of its top


class NoSpotsError(ValueError):
    """No lenslet lattice could be found in the image (no spots, too few, or no consistent lattice)."""


def lattice_coordinates(indices: np.ndarray, lattice: str) -> np.ndarray:
    """Ideal lattice coordinates (unit pitch) of lattice indices.

    Args:
        indices: ``(N, 2)`` integer ``(row, col)`` lattice indices.
        lattice: ``"hex"`` or ``"rect"``.

    Returns:
        ``(N, 2) float64`` ``(u, v)``: ``u = col + (row % 2) / 2`` (hex) or ``col`` (rect), ``v = row * sqrt(3) / 2``
        (hex) or ``row`` (rect); u grows with image x, v with image y.
    """
    _check_lattice(lattice)
    idx = np.asarray(indices, dtype=np.int64).reshape(-1, 2)
    r, c = idx[:, 0], idx[:, 1]
    u = c + (0.5 * (r % 2) if lattice == "hex" else 0.0)
    return np.stack([u.astype(np.float64), r * _ROW_STEP[lattice]], axis=1)


@dataclass
class LatticeFit:
    """Detected lenslet centres and the lattice fitted to them.

    Attributes:
        lattice: ``"hex"`` or ``"rect"``.
        centres: ``(N, 2) float64`` detected sub-pixel spot centres, pixels (x = col, y = row; origin at the
            centre of the top-left pixel), sorted row-major by lattice index.
        indices: ``(N, 2) int64`` lattice indices ``(row, col)`` of ``centres`` (see the module's conventions).
        homography: ``(3, 3) float64`` map from ideal lattice coordinates ``(u, v, 1)`` (unit pitch, see
            :func:`lattice_coordinates`) to undistorted pixels: the homography part of the lattice model (see
            :meth:`predicted`), fitted with ``distortion`` by least squares to all ``centres``. With no
            distortion (``distortion == 0``) it is the least-squares homography of the lattice.
        residuals: ``(N, 2) float64`` detected minus fitted lattice position (:meth:`predicted`), pixels.
        rms_px: RMS length of ``residuals``, pixels: the residual of the lattice model (homography + radial
            distortion, or the homography alone where the distortion was not significant).
        pitch_px: lenslet spacing along a row at the image centre (local derivative of the lattice model),
            pixels.
        rotation_deg: direction of the rows at the image centre, degrees counter-clockwise as seen on screen
            (image y points down); the rows are the lattice direction closest to the image x axis, so it lies
            within about +-30 deg (hex) or +-45 deg (rect). For a camera that faces the array squarely it has
            the sign of ``LensArray.rotation``.
        origin: ``(2,) float64`` pixel position of lattice index ``(0, 0)`` (from the lattice model).
        image_shape: ``(H, W)`` of the image.
        spot_sigma_px: spots: estimated standard deviation of the spots' blur, pixels; white images: radius of
            the centroid window (half the pitch), pixels.
        rejected: detections dropped by the lattice fit (off the lattice, or a second spot on one node).
        expected_shape: ``(rows, cols)`` of the array if it was given, else None.
        distortion: ``(2,) float64`` radial distortion ``(k1, k2)`` of the lattice model (zeros: none
            significant); ``k1 < 0`` barrel, ``k1 > 0`` pincushion.
        distortion_centre: ``(2,) float64`` centre ``c`` of the radial distortion, pixels (default: the
            image centre).
        distortion_scale: ``s``, the radius (pixels) that normalises ``rho`` (default: the image's
            half-diagonal, ``hypot(H - 1, W - 1) / 2``).
        homography_rms_px: RMS residual of the least-squares homography alone through the same ``centres``
            (equal to ``rms_px`` when ``distortion`` is zero; much larger than it on a distorted image).
        kind: ``"spots"`` or ``"white"``, the kind of image the centres come from.
    """

    lattice: str
    centres: np.ndarray
    indices: np.ndarray
    homography: np.ndarray
    residuals: np.ndarray
    rms_px: float
    pitch_px: float
    rotation_deg: float
    origin: np.ndarray
    image_shape: tuple[int, int]
    spot_sigma_px: float
    rejected: int = 0
    expected_shape: tuple[int, int] | None = None
    distortion: np.ndarray = field(default_factory=lambda: np.zeros(2))
    distortion_centre: np.ndarray | None = None
    distortion_scale: float = 0.0
    homography_rms_px: float | None = None
    kind: str = "spots"

    def __post_init__(self) -> None:
        h, w = self.image_shape
        self.distortion = np.asarray(self.distortion, dtype=np.float64).reshape(2)
        if self.distortion_centre is None:
            self.distortion_centre = np.array([(w - 1) / 2.0, (h - 1) / 2.0])
        self.distortion_centre = np.asarray(self.distortion_centre, dtype=np.float64).reshape(2)
        if not self.distortion_scale > 0:
            self.distortion_scale = max(0.5 * math.hypot(h - 1, w - 1), 1.0)
        if self.homography_rms_px is None:
            self.homography_rms_px = self.rms_px

    @property
    def _model(self) -> _Model:
        return _Model(self.homography, self.distortion, self.distortion_centre, float(self.distortion_scale))

    def predicted(self, indices: np.ndarray) -> np.ndarray:
        """Fitted lattice positions of lattice indices (the lattice model of the module's docstring).

        Args:
            indices: ``(N, 2)`` integer ``(row, col)`` lattice indices (any, also of lenslets not detected).

        Returns:
            ``(N, 2) float64`` pixels (x, y): ``homography``, then the radial ``distortion`` about
            ``distortion_centre``.
        """
        return _model_apply(self._model, lattice_coordinates(indices, self.lattice))

    def to_lattice(self, points: np.ndarray) -> np.ndarray:
        """Ideal lattice coordinates of pixel positions (the inverse of the lattice model).

        Args:
            points: ``(N, 2)`` pixels (x, y).

        Returns:
            ``(N, 2) float64`` ideal ``(u, v)`` (unit pitch, see :func:`lattice_coordinates`).
        """
        return _model_inverse(self._model, np.asarray(points, dtype=np.float64).reshape(-1, 2))

    @property
    def max_residual_px(self) -> float:
        """Largest residual length, pixels."""
        return float(np.max(np.linalg.norm(self.residuals, axis=1))) if len(self.residuals) else 0.0

    @property
    def shape(self) -> tuple[int, int]:
        """``(rows, cols)`` spanned by the detected indices (``max + 1``)."""
        return int(self.indices[:, 0].max()) + 1, int(self.indices[:, 1].max()) + 1

    def summary(self) -> str:
        """Human-readable multi-line description of the fit (lattice, counts, pitch, rotation, residuals)."""
        rows, cols = self.shape
        count = f"{len(self.centres)} lenslets in {rows} rows x {cols} columns"
        if self.expected_shape is not None:
            er, ec = self.expected_shape
            count += f" (array: {er} x {ec} = {er * ec})"
        ox, oy = self.origin
        size = (f"spot sigma {self.spot_sigma_px:.2f} px" if self.kind == "spots"
                else f"white image, centroid window radius {self.spot_sigma_px:.2f} px")
        if np.any(self.distortion != 0):
            k1, k2 = self.distortion
            cx, cy = self.distortion_centre
            model = (f"lattice model: homography + radial distortion k1 {k1:+.5f}, k2 {k2:+.5f} about "
                     f"({cx:.1f}, {cy:.1f}) px (rho = radius / {self.distortion_scale:.1f} px); homography "
                     f"alone: RMS {self.homography_rms_px:.4f} px")
        else:
            model = "lattice model: homography (no significant radial distortion)"
        return "\n".join([
            f"lattice: {self.lattice}, {count}",
            f"pitch: {self.pitch_px:.3f} px along rows at the image centre; "
            f"rotation: {self.rotation_deg:+.3f} deg (counter-clockwise)",
            f"origin (row 0, col 0): ({ox:.3f}, {oy:.3f}) px; {size}",
            model,
            f"lattice fit residuals: RMS {self.rms_px:.4f} px, max {self.max_residual_px:.4f} px; "
            f"{self.rejected} detection(s) off the lattice dropped",
        ])


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


# ----------------------------------------------------------------------------------------------- helpers
def _check_lattice(lattice: str) -> None:
    if lattice not in _ROW_STEP:
        raise ValueError(f"lattice must be 'hex' or 'rect', got {lattice!r}")


def _check_shape(expected_shape) -> tuple[int, int]:
    try:
        rows, cols = (int(v) for v in expected_shape)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"expected_shape must be (rows, cols), got {expected_shape!r}") from exc
    if rows < 1 or cols < 1:
        raise ValueError(f"expected_shape must be positive (rows, cols), got {expected_shape!r}")
    return rows, cols


def _as_grey(image: np.ndarray) -> np.ndarray:
    arr = np.asarray(image)
    if arr.ndim == 2 and arr.dtype.kind == "f":
        img = arr.astype(np.float64)
    else:
        from lftransfer.calibration.images import to_grey

        img = to_grey(arr)
    if min(img.shape) < 3:
        raise ValueError(f"image of shape {img.shape} is too small to hold lenslet spots")
    return np.nan_to_num(img, nan=0.0, posinf=0.0, neginf=0.0)


def _apply(h: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """Homography ``h`` applied to ``(N, 2)`` points."""
    q = np.asarray(pts, dtype=np.float64) @ h[:, :2].T + h[:, 2]
    return q[:, :2] / q[:, 2:3]


def _noise_sigma(values: np.ndarray, clipped: bool) -> float:
    """Background noise sigma from one half of the distribution, leaving out bright pixels iteratively.

    Args:
        values: the (background-subtracted) image.
        clipped: the image's dark background was clipped (many pixels at the smallest code): the lower half of
            the distribution is then squeezed, so the upper half (84th percentile minus median) is used;
            otherwise the lower half (median minus 16th percentile), which dense spots do not widen.

    Pixels above median + 3 sigma (spots, which can cover a third of the image) are left out, and the estimate
    repeated, until none is left out.
    """
    v = values.ravel()
    if v.size > 400_000:
        v = v[:: v.size // 200_000]                               # a sample is enough
    q = 84.134 if clipped else 15.866

    def estimate(x):
        med, other = np.percentile(x, [50.0, q])
        return float(med), float(abs(other - med))

    med, sigma = estimate(v)
    for _ in range(10):
        kept = v[v < med + 3.0 * sigma]
        if kept.size < 16 or kept.size == v.size:
            break
        v = kept
        med, sigma = estimate(v)
    return sigma


def _background(img: np.ndarray, mask: np.ndarray | None = None) -> np.ndarray:
    """Smooth background: median of 16 (32 for images >= 256 px) pixel blocks, 3 x 3 block median, bilinear.

    Args:
        img: ``(H, W)`` image.
        mask: ``(H, W) bool``, True on pixels to leave out (spots); blocks with nothing left take the median
            of the other blocks.
    """
    h, w = img.shape
    b = 32 if min(h, w) >= 256 else 16
    nh, nw = -(-h // b), -(-w // b)
    data = img if mask is None else np.where(mask, np.nan, img)
    padded = np.pad(data, ((0, nh * b - h), (0, nw * b - w)), mode="edge")
    blocks = padded.reshape(nh, b, nw, b).transpose(0, 2, 1, 3).reshape(nh, nw, b * b)
    if mask is None:
        med = np.median(blocks, axis=2)
    else:
        counts = np.isfinite(blocks).sum(axis=2)
        ordered = np.sort(np.where(np.isfinite(blocks), blocks, np.inf), axis=2)       # NaN (masked) last
        lo = np.take_along_axis(ordered, np.maximum(counts - 1, 0)[..., None] // 2, axis=2)[..., 0]
        hi = np.take_along_axis(ordered, np.minimum(counts // 2, b * b - 1)[..., None], axis=2)[..., 0]
        some = counts >= max(8, b * b // 16)
        med = np.where(some, 0.5 * (lo + hi), np.nan)
        med[~some] = np.median(med[some]) if some.any() else float(np.median(img))
    med = median_filter(med, size=3, mode="nearest")
    return cv2.resize(med.astype(np.float32), (nw * b, nh * b), interpolation=cv2.INTER_LINEAR)[:h, :w].astype(
        np.float64)


def _blur(res: np.ndarray) -> np.ndarray:
    return cv2.GaussianBlur(res.astype(np.float32), (0, 0), 1.0, borderType=cv2.BORDER_REPLICATE)


def _residual(img: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """Background-subtracted image (hot pixels replaced), its smoothed version (sigma 1 px) and that one's noise.

    The background and the noise are estimated up to three times, each time without the pixels that the
    previous pass found bright (spots and their wings, grown by 3 px), so that dense spots do not raise them.
    Hot pixels (more than 5 noise sigmas and more than 80 % of their own background-subtracted value above the
    median of their 3 x 3 neighbourhood; a Gaussian spot's peak is that sharp only for sigma < ~0.55 px) then
    take that median.
    """
    clipped = bool(np.count_nonzero(img <= img.min()) >= 0.02 * img.size)
    res = img - _background(img)
    mask = np.zeros(img.shape, bool)
    for _ in range(3):
        smooth = _blur(res)
        sample = smooth[~mask]
        noise = _noise_sigma(sample, clipped)
        bright = smooth > np.median(sample) + 3.0 * noise
        if not bright.any() or bright.mean() > 0.9:
            break
        grown = cv2.dilate(bright.astype(np.uint8), np.ones((7, 7), np.uint8)).astype(bool)
        mask = grown if grown.mean() <= 0.9 else bright
        res = img - _background(img, mask)
    med3 = cv2.medianBlur(res.astype(np.float32), 3).astype(np.float64)
    spike = res - med3
    hot = (spike > _SNR * _noise_sigma(res[~mask], clipped)) & (spike > _HOT * res)
    if hot.any():
        img = np.where(hot, img - res + med3, img)
        res = img - _background(img, mask | hot)
    smooth = _blur(res)
    return res, smooth, _noise_sigma(smooth[~mask], clipped)


def _detect_spots(img: np.ndarray) -> tuple[np.ndarray, float]:
    """Sub-pixel spot centres ``(N, 2)`` (x, y) pixels and the spots' sigma, pixels."""
    h, w = img.shape
    res, smooth, noise = _residual(img)
    top = float(smooth.max())
    if not top > 0:
        raise NoSpotsError("no lenslet spots found: the image is uniform (no bright spots on a darker background)")
    floor = max(_SNR * noise, 1e-4 * top)
    peaks = (smooth >= cv2.dilate(smooth, np.ones((5, 5), np.uint8))) & (smooth > floor)
    n, _, _, cent = cv2.connectedComponentsWithStats(peaks.astype(np.uint8), connectivity=8)
    if n <= 1:
        raise NoSpotsError(f"no lenslet spots found: nothing stands above the noise ({noise:.2g} of full scale)")
    xy = np.rint(cent[1:]).astype(np.int64)                          # plateaus -> one peak each
    xy[:, 0] = np.clip(xy[:, 0], 0, w - 1)
    xy[:, 1] = np.clip(xy[:, 1], 0, h - 1)
    x, y = xy[:, 0], xy[:, 1]
    amp = smooth[y, x].astype(np.float64)
    if len(xy) < 2:
        return xy.astype(np.float64), 1.0
    # Relative thresholds: 10 % of the brightest spot within about two pitches, 5 % of the bright ones anywhere.
    strong = amp >= 0.3 * np.percentile(amp, 90)
    if strong.sum() >= 2:
        d, _ = cKDTree(xy[strong]).query(xy[strong], k=2)
        pitch0 = float(np.median(d[:, 1]))
    else:
        pitch0 = float(max(h, w))
    k = min(19, len(xy))
    d, j = cKDTree(xy).query(xy, k=k, distance_upper_bound=2.2 * pitch0)
    neighbour_amp = np.where(np.isfinite(d), amp[np.minimum(j, len(xy) - 1)], 0.0)
    keep = (amp >= _REL * neighbour_amp.max(axis=1)) & (amp >= _REL_GLOBAL * np.percentile(amp, 95))
    xy, amp = xy[keep], amp[keep]
    sigma = _spot_sigma(res, xy, amp, pitch0)
    centres, ok = _windowed_centroids(res, xy, sigma, pitch0)
    margin = max(2.5 * sigma, 2.0)
    ok &= (centres[:, 0] >= margin) & (centres[:, 0] <= w - 1 - margin)
    ok &= (centres[:, 1] >= margin) & (centres[:, 1] <= h - 1 - margin)
    return centres[ok], sigma


def _spot_sigma(res: np.ndarray, xy: np.ndarray, amp: np.ndarray, pitch0: float) -> float:
    """Median Gaussian sigma of the brighter half of the spots, from 3-point log-parabolas along x and y."""
    h, w = res.shape
    inner = (xy[:, 0] >= 1) & (xy[:, 0] <= w - 2) & (xy[:, 1] >= 1) & (xy[:, 1] <= h - 2)
    sel = inner & (amp >= np.median(amp))
    x, y = xy[sel, 0], xy[sel, 1]
    sig = []
    for lo, mid, hi in ((res[y, x - 1], res[y, x], res[y, x + 1]), (res[y - 1, x], res[y, x], res[y + 1, x])):
        good = (lo > 0) & (mid > 0) & (hi > 0)
        with np.errstate(divide="ignore", invalid="ignore"):
            d2 = np.log(lo[good]) - 2 * np.log(mid[good]) + np.log(hi[good])
        sig.append(np.sqrt(-1.0 / d2[d2 < 0]))
    sig = np.concatenate(sig)
    sigma = float(np.median(sig)) if sig.size else 1.2
    return float(np.clip(sigma, 0.6, max(0.6, pitch0 / 6.0)))


def _windowed_centroids(res: np.ndarray, xy: np.ndarray, sigma: float, pitch: float, iterations: int = 60
                        ) -> tuple[np.ndarray, np.ndarray]:
    """Gaussian-windowed centroids (window sigma = spot sigma) around integer peaks, iterated to convergence.

    Each spot's local background (median of an annulus between the spot and its neighbours) is subtracted
    first; pixels outside the image take no part. The fixed point is the centre of any symmetric spot.

    Args:
        res: ``(H, W)`` background-subtracted image.
        xy: ``(N, 2) int64`` integer peaks (x, y).
        sigma: spot sigma, pixels (also the window's).
        pitch: typical distance between neighbouring spots, pixels.
        iterations: most iterations.

    Returns:
        ``(N, 2) float64`` centres (x, y) pixels and ``(N,) bool`` convergence flags.
    """
    rad = int(math.ceil(4.0 * sigma)) + 1                       # window: the weights are < 1e-3 beyond
    r_in = min(4.0 * sigma + 1.0, max(3.0 * sigma, 0.3 * pitch))
    r_out = r_in + 2.0
    half = max(rad, int(math.ceil(r_out)))
    pad = np.pad(res, half, mode="constant", constant_values=np.nan)
    off = np.arange(-half, half + 1)
    cx, cy = xy[:, 0], xy[:, 1]
    patch = pad[(cy + half)[:, None, None] + off[None, :, None], (cx + half)[:, None, None] + off[None, None, :]]
    dist = np.hypot(off[:, None], off[None, :])
    annulus = (dist >= r_in) & (dist <= r_out)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)           # all-NaN annulus at a corner: no correction
        local_bg = np.nan_to_num(np.nanmedian(patch[:, annulus], axis=1), nan=0.0)
    core = (np.maximum(np.abs(off)[:, None], np.abs(off)[None, :]) <= rad)[None]
    values = np.where(core & np.isfinite(patch), patch - local_bg[:, None, None], 0.0)
    gx = (cx[:, None, None] + off[None, None, :]).astype(np.float64)
    gy = (cy[:, None, None] + off[None, :, None]).astype(np.float64)
    p = xy.astype(np.float64).copy()
    ok = np.ones(len(p), bool)
    inv2s2 = 1.0 / (2.0 * sigma * sigma)
    for _ in range(iterations):
        dx = gx - p[:, 0, None, None]
        dy = gy - p[:, 1, None, None]
        wv = np.exp(-(dx * dx + dy * dy) * inv2s2) * values
        s = wv.sum(axis=(1, 2))
        ok &= s > 0
        s = np.where(s > 0, s, 1.0)
        # For a Gaussian spot of the window's sigma, 2 * (windowed centroid - p) is the exact step; 1.5
        # under-relaxes it (robust to a wrong sigma or background), converging by a factor ~4 per iteration.
        step = 1.5 * np.stack([(wv * dx).sum(axis=(1, 2)), (wv * dy).sum(axis=(1, 2))], axis=1) / s[:, None]
        step = np.where(ok[:, None], np.clip(step, -1.0, 1.0), 0.0)
        p += step
        if np.max(np.abs(step), initial=0.0) < 1e-6:
            break
    ok &= np.all(np.abs(p - xy) <= 2.0, axis=1) & np.all(np.isfinite(p), axis=1)
    ok &= np.all(np.abs(step) < 1e-3, axis=1)                   # did not converge: no reliable centre
    return p, ok


# ------------------------------------------------------------------------------------------- white images
def _detect_white(img: np.ndarray, lattice: str) -> tuple[np.ndarray, float]:
    """Sub-pixel sub-image centres of a white image (see the module's docstring).

    The first pass uses a disk window of half the pitch everywhere. The second one divides out each
    sub-image's vignetting gradient and follows the distorted lattice: sub-images apart from each other (their
    mean radial profile falls to the dark gap within half a pitch) get a disk of half their local pitch
    (median distance to their nearest neighbours), touching ones their own lattice cell (:func:`_local_cells`,
    1 px in), so that no neighbour reaches into the window. Near the image border the window is cut by a
    disk that stays inside the image, down to the sub-images' extent (half the pitch if they touch); sub-images
    whose window would have to be smaller, and those whose mean brightness is below 75 % of the median of
    their neighbours' (cut by the edge of the lit area), are dropped.

    Args:
        img: ``(H, W)`` grey image.
        lattice: ``"hex"`` or ``"rect"`` (the shape of the cells).

    Returns:
        ``(N, 2) float64`` centres (x, y), pixels, and the median window radius (half the pitch), pixels.
    """
    h, w = img.shape
    pitch = _autocorr_pitch(img)
    env = _envelope(img, pitch)
    top = float(np.percentile(env, 99.0))
    if not top > 0:
        raise NoSpotsError("no lenslet sub-images found: the image is dark")
    norm = img / np.maximum(env, 0.05 * top)
    smooth = cv2.GaussianBlur(norm.astype(np.float32), (0, 0), _WHITE_SMOOTH * pitch,
                              borderType=cv2.BORDER_REPLICATE)
    size = 2 * int(round(0.35 * pitch)) + 1
    peaks = smooth >= cv2.dilate(smooth, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (size, size)))
    size = 2 * int(round(0.65 * pitch)) + 1
    contrast = smooth - cv2.erode(smooth, np.ones((size, size), np.uint8))          # separable: fast
    peaks &= (env > _WHITE_ENVELOPE * top) & (contrast > 0)
    n, _, _, cent = cv2.connectedComponentsWithStats(peaks.astype(np.uint8), connectivity=8)
    if n <= 1:
        raise NoSpotsError("no lenslet sub-images found: no local maxima in the lit part of the image")
    xy = np.rint(cent[1:]).astype(np.int64)
    xy[:, 0] = np.clip(xy[:, 0], 0, w - 1)
    xy[:, 1] = np.clip(xy[:, 1], 0, h - 1)
    con = contrast[xy[:, 1], xy[:, 0]].astype(np.float64)
    xy = xy[con >= _WHITE_REL * np.percentile(con, 75)].astype(np.float64)
    if len(xy) >= 2:                                             # the pitch of the detections themselves
        d, _ = cKDTree(xy).query(xy, k=2)
        near = np.abs(d[:, 1] / pitch - 1.0) < 0.3
        if near.any():
            pitch = float(np.median(d[near, 1]))
    centres, ok = _disk_centroids(img, xy, _WHITE_WINDOW * pitch)
    centres = centres[ok]
    if len(centres) < 4:
        return centres, _WHITE_WINDOW * pitch                    # too few: find_lenslet_centres says so
    local_pitch = _local_pitch(centres, pitch)
    gamma, bright, typical = _relative_gradient(img, centres, _WHITE_BRIGHT * local_pitch, local_pitch)
    nominal = _WHITE_WINDOW * local_pitch
    extent = _subimage_extent(img, centres, nominal, bright)
    # Second pass. Sub-images apart: a disk of half the local pitch, smaller near the image border down to
    # the sub-images' own extent. Touching sub-images: the sub-image's own lattice cell (1 px in), which
    # keeps the neighbours out, cut by a disk that keeps it inside the image, down to half the pitch. A
    # sub-image cut by the border is dropped.
    if extent is None:
        extent = nominal - 0.5
        axes, apothem = _local_cells(centres, local_pitch, lattice)
        radius = np.minimum(_CELL_DISK * local_pitch, _inset(centres, (h, w)))
    else:
        extent = np.minimum(extent, nominal - 0.5)
        axes = apothem = None
        radius = np.minimum(nominal, _inset(centres, (h, w)))
    keep = (bright >= 0.75 * typical) & (radius >= extent)
    extent, radius, nominal = extent[keep], radius[keep], nominal[keep]
    if axes is not None:
        axes, apothem = axes[keep], apothem[keep]
    centres, ok = _disk_centroids(img, centres[keep], radius, gamma[keep], axes, apothem)
    ok[ok] &= np.minimum(radius[ok], _inset(centres[ok], (h, w)) + 0.5) >= extent[ok]
    centres, radius = centres[ok], np.minimum(radius[ok], nominal[ok])
    if len(centres) >= 2:                                        # two peaks that found one sub-image: one
        pairs = cKDTree(centres).query_pairs(0.3 * pitch, output_type="ndarray")
        if len(pairs):
            keep = np.ones(len(centres), bool)
            keep[pairs[:, 1]] = False
            centres, radius = centres[keep], radius[keep]
    return centres, float(np.median(radius)) if len(radius) else _WHITE_WINDOW * pitch


def _inset(xy: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """``(N,)`` distance (pixels) of points to the nearest image border (the outermost pixel centres)."""
    h, w = shape
    return np.minimum(np.minimum(xy[:, 0], w - 1 - xy[:, 0]), np.minimum(xy[:, 1], h - 1 - xy[:, 1]))


def _subimage_extent(img: np.ndarray, centres: np.ndarray, radius: np.ndarray, bright: np.ndarray
                     ) -> float | None:
    """Radius (pixels) of the sub-images: where their mean radial profile first falls to 5 % above its floor.

    The profile (0.25 px bins, each sub-image divided by its own brightness) is averaged over up to 400
    sub-images nearest the image centre, out to their window radius. Sub-images that touch never fall that
    far: then (or with too few sub-images) None.
    """
    h, w = img.shape
    sel = np.argsort(np.hypot(centres[:, 0] - (w - 1) / 2, centres[:, 1] - (h - 1) / 2))[:400]
    sel = sel[bright[sel] > 0]
    if len(sel) < 4:
        return None
    half = int(math.ceil(radius[sel].max())) + 1
    offi = np.arange(-half, half + 1)
    base = np.rint(centres[sel]).astype(np.int64)
    pad = np.pad(img.astype(np.float64), half, mode="constant", constant_values=np.nan)
    patch = pad[(base[:, 1] + half)[:, None, None] + offi[None, :, None],
                (base[:, 0] + half)[:, None, None] + offi[None, None, :]] / bright[sel, None, None]
    d = np.hypot((base[:, 0] - centres[sel, 0])[:, None, None] + offi[None, None, :],
                 (base[:, 1] - centres[sel, 1])[:, None, None] + offi[None, :, None])
    use = np.isfinite(patch) & (d <= radius[sel, None, None])
    bins = (d[use] / 0.25).astype(np.int64)
    counts = np.bincount(bins)
    prof = np.bincount(bins, weights=patch[use]) / np.maximum(counts, 1)
    prof = prof[counts > 0] if np.all(counts > 0) else prof[: np.argmin(counts > 0)]
    if len(prof) < 8:
        return None
    peak_at = int(np.argmax(prof))
    peak, floor = float(prof[peak_at]), float(prof[peak_at:].min())
    low = np.flatnonzero(prof[peak_at:] <= floor + 0.05 * (peak - floor))
    if not (len(low) and peak > floor) or (peak_at + low[0] + 1) * 0.25 > 0.98 * float(np.min(radius[sel])):
        return None
    return (peak_at + low[0] + 1) * 0.25


def _local_cells(centres: np.ndarray, local_pitch: np.ndarray, lattice: str) -> tuple[np.ndarray, np.ndarray]:
    """Each sub-image's lattice cell: directions to its neighbours and half their distances.

    The neighbours within 0.7..1.3 local pitches are sorted onto the lattice's K axes (3 for ``hex``, 2 for
    ``rect``) by their direction relative to the lattice's overall orientation; an axis' direction is the
    mean of its neighbours' (both signs) and its apothem half their mean distance, so the cell is centrally
    symmetric and follows the local distortion. Axes without neighbours take the overall direction and the
    mean of the other apothems (or half the local pitch).

    Returns:
        ``(N, K, 2)`` unit axes and ``(N, K)`` apothems, pixels.
    """
    n = len(centres)
    kk = 3 if lattice == "hex" else 2
    d, j = cKDTree(centres).query(centres, k=min(2 * kk + 3, n))
    d, j = d[:, 1:], j[:, 1:]
    near = (d > 0.7 * local_pitch[:, None]) & (d < 1.3 * local_pitch[:, None]) & (j < n)
    vec = centres[np.minimum(j, n - 1)] - centres[:, None, :]
    phi = np.arctan2(vec[..., 1], vec[..., 0])
    z = np.exp(2j * kk * phi)[near]
    theta = float(np.angle(np.mean(z))) / (2 * kk) if len(z) else 0.0
    sector = np.rint((phi - theta) / (math.pi / kk)).astype(np.int64)
    axis = sector % kk
    sign = np.where(sector % (2 * kk) < kk, 1.0, -1.0)                # the neighbours on both sides, one way
    unit = vec / np.maximum(d, 1e-9)[..., None] * sign[..., None]
    axes = np.zeros((n, kk, 2))
    apothem = np.zeros((n, kk))
    for k in range(kk):
        on = near & (axis == k)
        cnt = on.sum(axis=1)
        mean_dir = np.einsum("nm,nmi->ni", on.astype(np.float64), unit)
        default = np.array([math.cos(theta + k * math.pi / kk), math.sin(theta + k * math.pi / kk)])
        norm = np.linalg.norm(mean_dir, axis=1, keepdims=True)
        axes[:, k] = np.where((cnt > 0)[:, None] & (norm > 0), mean_dir / np.maximum(norm, 1e-12), default)
        apothem[:, k] = np.where(cnt > 0, 0.5 * (on * d).sum(axis=1) / np.maximum(cnt, 1), np.nan)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)           # no neighbour on any axis: half the pitch
        fill = np.nanmean(apothem, axis=1)
    fill = np.where(np.isfinite(fill), fill, 0.5 * local_pitch)
    apothem = np.where(np.isfinite(apothem), apothem, fill[:, None])
    return axes, apothem


def _local_pitch(xy: np.ndarray, pitch: float) -> np.ndarray:
    """``(N,)`` median distance of each point to its neighbours within 0.7..1.3 ``pitch`` (else ``pitch``)."""
    n = len(xy)
    if n < 2:
        return np.full(n, pitch)
    d, _ = cKDTree(xy).query(xy, k=min(7, n))
    d = np.where((d[:, 1:] > 0.7 * pitch) & (d[:, 1:] < 1.3 * pitch), d[:, 1:], np.nan)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)           # no neighbour: NaN -> the global pitch
        local = np.nanmedian(d, axis=1)
    return np.where(np.isfinite(local), local, pitch)


def _looks_white(img: np.ndarray) -> bool:
    """Mostly bright (median above a quarter of the maximum) with a lattice's period: a white image."""
    if not float(np.median(img)) > 0.25 * float(img.max()):
        return False
    try:
        _autocorr_pitch(img)
    except NoSpotsError:
        return False
    return True


def _autocorr_pitch(img: np.ndarray) -> float:
    """Lattice pitch (pixels) of a white image: distance of the nearest autocorrelation peak.

    The central crop (up to 512 px square) is high-passed (minus a Gaussian blur of an eighth of its size),
    Hann-windowed and zero-padded, so the autocorrelation is linear and falls off with the lag; its highest
    local maximum beyond 3 px (and within a quarter of the crop) is one of the nearest lattice neighbours; it
    must reach 10 % of the zero-lag value (a periodic image, not noise).
    """
    h, w = img.shape
    n = min(h, w, 512)
    if n < 16:
        raise NoSpotsError(f"no lenslet sub-images found: the image ({h} x {w}) is too small")
    y0, x0 = (h - n) // 2, (w - n) // 2
    crop = img[y0:y0 + n, x0:x0 + n].astype(np.float64)
    crop = crop - cv2.GaussianBlur(crop, (0, 0), n / 8.0, borderType=cv2.BORDER_REFLECT)
    win = np.hanning(n)
    spec = np.fft.rfft2(crop * win[:, None] * win[None, :], s=(2 * n, 2 * n))
    ac = np.fft.fftshift(np.fft.irfft2(np.abs(spec) ** 2, s=(2 * n, 2 * n)))
    m = n // 4
    ac = ac[n - m:n + m + 1, n - m:n + m + 1].astype(np.float32)
    if not ac[m, m] > 0:
        raise NoSpotsError("no lenslet sub-images found: the image is uniform")
    off = np.arange(-m, m + 1)
    r = np.hypot(off[:, None], off[None, :])
    local = (ac >= cv2.dilate(ac, np.ones((5, 5), np.uint8))) & (r > 3.0) & (r < m - 2)
    if not local.any():
        raise NoSpotsError("no lenslet sub-images found: the image has no periodic structure")
    vals = np.where(local, ac, -np.inf)
    best = float(vals.max())
    if not best > 0.1 * ac[m, m]:
        raise NoSpotsError("no lenslet sub-images found: the image has no periodic structure")
    r1 = float(r.ravel()[np.argmax(vals)])
    close = local & (ac > 0.5 * best) & (r < 1.3 * r1)           # the shell of nearest neighbours
    return float(np.median(r[close]))


def _envelope(img: np.ndarray, pitch: float) -> np.ndarray:
    """Vignetting envelope of a white image: Gaussian blur of sigma one pitch (on a reduced copy), full size.

    The blur attenuates the lattice's period by ``exp(-2 pi^2)``; the copy is reduced by block means of less
    than a sixth of the pitch, well below the lattice's Nyquist limit.
    """
    h, w = img.shape
    f = max(1, int(pitch // 6))
    small = cv2.resize(img.astype(np.float32), (max(1, w // f), max(1, h // f)), interpolation=cv2.INTER_AREA)
    small = cv2.GaussianBlur(small, (0, 0), pitch / f, borderType=cv2.BORDER_REFLECT)
    return cv2.resize(small, (w, h), interpolation=cv2.INTER_LINEAR).astype(np.float64)


def _disk_centroids(img: np.ndarray, xy: np.ndarray, radius, gamma: np.ndarray | None = None,
                    axes: np.ndarray | None = None, apothem: np.ndarray | None = None, iterations: int = 60,
                    chunk: int = 1024) -> tuple[np.ndarray, np.ndarray]:
    """Centroids of the image within a flat disk (or cell) window (soft edge) iterated to their fixed points.

    The fixed point of a centrally symmetric window is the centre of any centrally symmetric sub-image it
    holds, neighbours included (a lattice is centrally symmetric about each node, to first order in the
    distortion). The disk window's weight is ``clip(((radius + 1)^2 - r^2) / (4 radius), 0, 1)``: 1 within
    about ``radius - 1``, 0 beyond ``radius + 1``. The iteration converges geometrically (what the window's
    rim cuts moves with it); it is sped up by extrapolating the geometric series of the steps (Aitken). The
    patches are cut around the rounded start with a 3 px margin around the window, the most a centre may
    move.

    Args:
        img: ``(H, W)`` image.
        xy: ``(N, 2)`` start positions (x, y), pixels.
        radius: ``(N,)`` window radii, pixels.
        gamma: ``(N, 2)`` relative brightness gradient (1/px) of each sub-image's surroundings, divided out of
            its window (``image / (1 + gamma . (x - start))``), or None.
        axes: ``(N, K, 2)`` unit vectors towards the neighbours (K = 3 for ``hex``, 2 for ``rect``) and
        apothem: ``(N, K)`` half the neighbour distances, pixels: the window is also cut to the sub-image's
            lattice cell, ``|axis . (x - c)| <= apothem - 1`` (weight falling from 1 to 0 over the 2 px inside
            that), which keeps the neighbours of touching sub-images out; or None.
        iterations: most iterations per stage.
        chunk: sub-images processed at once (memory).

    Returns:
        ``(N, 2) float64`` centres (x, y) and ``(N,) bool`` flags (converged to 1e-3 px, moved less than a
        third of the radius from the start, window not empty).
    """
    radius = np.broadcast_to(np.asarray(radius, dtype=np.float64), (len(xy),))
    half = int(math.ceil(radius.max(initial=1.0) + 1.0)) + 3
    pad = np.pad(img.astype(np.float32), half, mode="constant", constant_values=np.nan)
    offi = np.arange(-half, half + 1)
    off = offi.astype(np.float32)
    outer2 = ((radius + 1.0) ** 2).astype(np.float32)[:, None, None]
    inv_ramp = (1.0 / (4.0 * radius)).astype(np.float32)[:, None, None]
    if axes is not None:
        ax32 = np.asarray(axes, dtype=np.float32)
        ap32 = (np.asarray(apothem, dtype=np.float64) - 1.0).astype(np.float32)   # weight 0 there, 1 at -2
    start = np.asarray(xy, dtype=np.float64)
    p = start.copy()
    ok = np.ones(len(p), bool)
    base = np.rint(p).astype(np.int64)
    for s in range(0, len(p), chunk):
        sl = slice(s, s + chunk)
        b = base[sl]
        patch = pad[(b[:, 1] + half)[:, None, None] + offi[None, :, None],
                    (b[:, 0] + half)[:, None, None] + offi[None, None, :]]
        patch = np.where(np.isfinite(patch), patch, np.float32(0.0))
        if gamma is not None:
            g = gamma[sl].astype(np.float32)
            rel = (b - start[sl]).astype(np.float32)
            tilt = 1.0 + g[:, 0, None, None] * (off[None, None, :] + rel[:, 0, None, None]) \
                + g[:, 1, None, None] * (off[None, :, None] + rel[:, 1, None, None])
            patch = patch / np.maximum(tilt, np.float32(0.1))
        q = p[sl] - b
        step = np.zeros_like(q)
        prev = np.zeros_like(q)
        active = np.ones(len(q), bool)
        good = np.ones(len(q), bool)
        for it in range(iterations):
            a = np.flatnonzero(active)
            if not len(a):
                break
            qa = q[a].astype(np.float32)
            r2 = (off[None, None, :] - qa[:, 0, None, None]) ** 2 + (off[None, :, None] - qa[:, 1, None, None]) ** 2
            wgt = np.clip((outer2[sl][a] - r2) * inv_ramp[sl][a], 0.0, 1.0)
            if axes is not None:                                 # cut to the cell
                dxa = off[None, None, :] - qa[:, 0, None, None]
                dya = off[None, :, None] - qa[:, 1, None, None]
                for k in range(ax32.shape[1]):
                    proj = np.abs(ax32[sl][a, k, 0, None, None] * dxa + ax32[sl][a, k, 1, None, None] * dya)
                    wgt = np.minimum(wgt, np.clip(0.5 * (ap32[sl][a, k, None, None] - proj), 0.0, 1.0))
            wv = wgt * patch[a]
            cols = wv.sum(axis=1, dtype=np.float64)          # (n, P): sums over rows
            rows = wv.sum(axis=2, dtype=np.float64)
            tot = cols.sum(axis=1)
            fine = tot > 0
            tot = np.where(fine, tot, 1.0)
            st = np.stack([cols @ offi, rows @ offi], axis=1) / tot[:, None] - q[a]
            st = np.where(fine[:, None], np.clip(st, -1.0, 1.0), 0.0)
            good[a] &= fine
            # Aitken: steps shrinking by a ratio rho sum to step / (1 - rho)
            pr = prev[a]
            rho = np.sum(st * pr, axis=1) / np.maximum(np.sum(pr * pr, axis=1), 1e-30)
            accel = np.where((it >= 1) & (rho > 0.0) & (rho < 0.95), 1.0 / (1.0 - np.clip(rho, 0.0, 0.9)), 1.0)
            prev[a] = st
            q[a] = np.clip(q[a] + st * accel[:, None], -3.0, 3.0)
            step[a] = st
            active[a] = np.max(np.abs(st), axis=1) >= 2e-5
        p[sl] = b + q
        ok[sl] &= good & np.all(np.abs(step) < 1e-3, axis=1)
    ok &= np.all(np.isfinite(p), axis=1) & (np.linalg.norm(p - start, axis=1) < radius / 3.0)
    return p, ok


def _relative_gradient(img: np.ndarray, centres: np.ndarray, radius: np.ndarray, pitch: np.ndarray
                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each sub-image's relative brightness gradient (1/px) from its neighbours' mean brightness.

    The mean of the image in each sub-image's window (symmetric, so blind to the sub-image's own tilt) is a
    sample of the vignetting at its centre; a plane fitted (least squares) to the samples within 2.3 pitches
    gives the gradient, divided by the plane's value at the centre. Zero where fewer than four neighbours or
    a degenerate spread.

    Args:
        img: ``(H, W)`` image.
        centres: ``(N, 2)`` sub-image centres, pixels.
        radius: ``(N,)`` window radii, pixels.
        pitch: ``(N,)`` local pitch, pixels.

    Returns:
        ``(N, 2) float64`` ``(d/dx, d/dy)`` of the relative brightness, ``(N,)`` window means and ``(N,)`` the
        median window mean of the sub-images within 1.5 pitches (itself included).
    """
    n = len(centres)
    half = int(math.ceil(radius.max(initial=1.0) + 1.0))
    offi = np.arange(-half, half + 1)
    base = np.rint(centres).astype(np.int64)
    pad = np.pad(img.astype(np.float32), half, mode="constant", constant_values=np.nan)
    bright = np.empty(n)
    for s in range(0, n, 2048):
        b, c, rad = base[s:s + 2048], centres[s:s + 2048], radius[s:s + 2048, None, None]
        patch = pad[(b[:, 1] + half)[:, None, None] + offi[None, :, None],
                    (b[:, 0] + half)[:, None, None] + offi[None, None, :]]
        dx = (b[:, 0] - c[:, 0])[:, None, None] + offi[None, None, :]
        dy = (b[:, 1] - c[:, 1])[:, None, None] + offi[None, :, None]
        wgt = np.clip(((rad + 1.0) ** 2 - dx * dx - dy * dy) / (4.0 * rad), 0.0, 1.0) * np.isfinite(patch)
        bright[s:s + 2048] = (wgt * np.nan_to_num(patch)).sum(axis=(1, 2)) / np.maximum(wgt.sum(axis=(1, 2)), 1e-9)
    if n < 4:
        return np.zeros((n, 2)), bright, bright.copy()
    k = min(19, n)
    d, j = cKDTree(centres).query(centres, k=k, distance_upper_bound=2.3 * float(np.max(pitch)))
    jj = np.minimum(j, n - 1)
    valid = (d <= 2.3 * pitch[:, None]).astype(np.float64)
    near = np.where(d <= 1.5 * pitch[:, None], bright[jj], np.nan)
    typical = np.nanmedian(near, axis=1)                         # itself at least: never all NaN
    rel = (centres[jj] - centres[:, None, :]) * valid[..., None]
    x = np.concatenate([valid[..., None], rel], axis=2)          # (N, k, 3): [1, dx, dy]
    a = np.einsum("nki,nkj->nij", x, x)
    rhs = np.einsum("nki,nk->ni", x, bright[jj] * valid)
    spread = np.linalg.eigvalsh(a[:, 1:, 1:] - np.einsum("ni,nj->nij", a[:, 0, 1:], a[:, 0, 1:])
                                / np.maximum(a[:, 0, 0], 1.0)[:, None, None])[:, 0]
    fine = (valid.sum(axis=1) >= 4) & (spread > 0.5 * pitch * pitch)
    gamma = np.zeros((n, 2))
    if fine.any():
        beta = np.linalg.solve(a[fine], rhs[fine][..., None])[..., 0]
        with np.errstate(divide="ignore", invalid="ignore"):
            g = beta[:, 1:] / beta[:, :1]
        gamma[fine] = np.where(np.isfinite(g) & (beta[:, :1] > 0), g, 0.0)
    return gamma, bright, typical


# ----------------------------------------------------------------------------------------------- lattice
class _Model(NamedTuple):
    """Lattice model: ideal ``(u, v)`` -> ``h`` -> undistorted pixels -> radial distortion about ``centre``."""

    h: np.ndarray                # (3, 3)
    k: np.ndarray                # (2,) k1, k2
    centre: np.ndarray           # (2,) pixels
    scale: float                 # pixels; rho = |q - centre| / scale


def _distort(q: np.ndarray, centre: np.ndarray, scale: float, k: np.ndarray) -> np.ndarray:
    """``(N, 2)`` undistorted pixels -> distorted: ``c + (q - c) (1 + k1 rho^2 + k2 rho^4)``."""
    d = (q - centre) / scale
    r2 = np.sum(d * d, axis=1, keepdims=True)
    return centre + scale * d * (1.0 + k[0] * r2 + k[1] * r2 * r2)


def _undistort(p: np.ndarray, centre: np.ndarray, scale: float, k: np.ndarray, iterations: int = 50
               ) -> np.ndarray:
    """Inverse of :func:`_distort` (fixed-point iteration; a few percent of distortion converge fast)."""
    if not np.any(k):
        return np.array(p, dtype=np.float64)
    d = (p - centre) / scale
    u = d.copy()
    for _ in range(iterations):
        r2 = np.sum(u * u, axis=1, keepdims=True)
        new = d / np.maximum(1.0 + k[0] * r2 + k[1] * r2 * r2, 0.1)
        if np.max(np.abs(new - u), initial=0.0) < 1e-13:
            u = new
            break
        u = new
    return centre + scale * u


def _model_apply(m: _Model, uv: np.ndarray) -> np.ndarray:
    return _distort(_apply(m.h, uv), m.centre, m.scale, m.k)


def _model_inverse(m: _Model, xy: np.ndarray) -> np.ndarray:
    return _apply(np.linalg.inv(m.h), _undistort(xy, m.centre, m.scale, m.k))


def _nearest_nodes(uv: np.ndarray, lattice: str) -> tuple[np.ndarray, np.ndarray]:
    """Nearest lattice nodes of ideal coordinates: ``(N, 2) int64`` (row, col) and their ``(N, 2)`` (u, v)."""
    r = np.rint(uv[:, 1] / _ROW_STEP[lattice]).astype(np.int64)
    shift = 0.5 * (r % 2) if lattice == "hex" else 0.0
    c = np.rint(uv[:, 0] - shift).astype(np.int64)
    idx = np.stack([r, c], axis=1)
    return idx, lattice_coordinates(idx, lattice)


def _keys(idx: np.ndarray) -> np.ndarray:
    """One int64 per (row, col) index pair."""
    return (idx[:, 0] + (1 << 24)) * (1 << 26) + (idx[:, 1] + (1 << 24))


def _closest_per_node(idx: np.ndarray, dist: np.ndarray) -> np.ndarray:
    """``(N,) bool``: True on the closest of the detections that share a node."""
    order = np.lexsort((dist, idx[:, 1], idx[:, 0]))
    first = np.ones(len(order), bool)
    first[1:] = np.any(idx[order][1:] != idx[order][:-1], axis=1)
    unique = np.zeros(len(idx), bool)
    unique[order[first]] = True
    return unique


def _homography(nodes: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Least-squares homography ideal ``(N, 2)`` -> pixels ``(N, 2)``, normalised to ``h[2, 2] = 1``."""
    if len(nodes) < 4 or len(np.unique(nodes[:, 0])) < 2 or len(np.unique(nodes[:, 1])) < 2:
        raise NoSpotsError(f"the {len(nodes)} detections on the lattice do not span two rows and columns; "
                           "cannot fit a lattice")
    h, _ = cv2.findHomography(nodes.astype(np.float64), points.astype(np.float64), 0)
    if h is None or not np.all(np.isfinite(h)) or abs(np.linalg.det(h)) < 1e-12:
        raise NoSpotsError(f"could not fit a lattice homography to {len(nodes)} detections")
    return h / h[2, 2]


def _fit_model(ideal: np.ndarray, points: np.ndarray, shape: tuple[int, int], radial: bool = True
               ) -> tuple[_Model, float, float]:
    """Lattice model (least squares) through ``points`` at ideal coordinates ``ideal``.

    The homography is OpenCV's least-squares one; with ``radial``, homography, ``k1``, ``k2`` and the
    distortion centre are then refined together (Levenberg-Marquardt, in coordinates normalised by the
    image's half-diagonal and the lattice's spread), with a weak prior holding the centre near the image
    centre. The radial terms are kept only if significant (see the module's docstring).

    Returns:
        The model, its RMS residual and the homography's alone, pixels.
    """
    h_img, w_img = shape
    c0 = np.array([(w_img - 1) / 2.0, (h_img - 1) / 2.0])
    scale = max(0.5 * math.hypot(h_img - 1, w_img - 1), 1.0)
    hom = _homography(ideal, points)
    res_h = points - _apply(hom, ideal)
    rss_h = float(np.sum(res_h ** 2))
    n = len(points)
    plain = _Model(hom, np.zeros(2), c0, scale)
    rms_h = math.sqrt(rss_h / n)
    spans = min(len(np.unique(np.round(ideal[:, 0], 6))), len(np.unique(np.round(ideal[:, 1], 6))))
    if not radial or n < 16 or spans < 3 or rss_h <= 0:
        return plain, rms_h, rms_h
    mu = ideal.mean(axis=0)
    su = float(np.sqrt(np.mean(np.sum((ideal - mu) ** 2, axis=1)))) or 1.0
    uvn = (ideal - mu) / su
    qn = (points - c0) / scale
    t_uv = np.array([[1 / su, 0, -mu[0] / su], [0, 1 / su, -mu[1] / su], [0, 0, 1.0]])
    t_px = np.array([[scale, 0, c0[0]], [0, scale, c0[1]], [0, 0, 1.0]])
    hn = np.linalg.inv(t_px) @ hom @ np.linalg.inv(t_uv)
    hn /= hn[2, 2]

    def residual(x):
        hh = np.append(x[:8], 1.0).reshape(3, 3)
        pred = _distort(_apply(hh, uvn), x[10:12], 1.0, x[8:10])
        return np.concatenate([((pred - qn) * scale).ravel(), _CENTRE_PRIOR_PX * x[10:12]])

    x0 = np.concatenate([hn.ravel()[:8], np.zeros(4)])
    try:
        sol = least_squares(residual, x0, method="lm", x_scale="jac", xtol=1e-12, ftol=1e-12)
    except (ValueError, np.linalg.LinAlgError):
        return plain, rms_h, rms_h
    hh = t_px @ np.append(sol.x[:8], 1.0).reshape(3, 3) @ t_uv
    model = _Model(hh / hh[2, 2], sol.x[8:10].copy(), c0 + scale * sol.x[10:12], scale)
    rss_r = float(np.sum((points - _model_apply(model, ideal)) ** 2))
    dof = 2 * n - 12
    f_stat = (rss_h - rss_r) / 4.0 / max(rss_r / dof, 1e-300)
    if not (np.all(np.isfinite(model.h)) and f_stat > _F_RADIAL and rss_r < 0.98 ** 2 * rss_h):
        return plain, rms_h, rms_h
    return model, math.sqrt(rss_r / n), rms_h


def _local_jacobians(points: np.ndarray, uv: np.ndarray, done: np.ndarray, which: np.ndarray, pitch: float
                     ) -> tuple[np.ndarray, np.ndarray]:
    """Local lattice Jacobians ``d(x, y) / d(u, v)`` at detections ``which`` from the assigned ones near them.

    Affine least-squares fit of the assigned detections within ``_JAC_REACH`` pitches (up to 13).

    Returns:
        ``(M, 2, 2)`` Jacobians and ``(M,) bool``: the fit was well posed (at least 4 nodes spanning two
        directions); where not, the Jacobian is left zero.
    """
    a = np.flatnonzero(done)
    k = min(13, len(a))
    d, j = cKDTree(points[a]).query(points[which], k=k, distance_upper_bound=_JAC_REACH * pitch)
    d, j = d.reshape(len(which), k), j.reshape(len(which), k)
    valid = np.isfinite(d).astype(np.float64)
    nb = a[np.minimum(j, len(a) - 1)]
    duv = (uv[nb] - uv[which][:, None, :]) * valid[..., None]
    dxy = (points[nb] - points[which][:, None, :]) * valid[..., None]
    x = np.concatenate([duv, valid[..., None]], axis=2)          # (M, k, 3): [du, dv, 1]
    a_mat = np.einsum("mki,mkj->mij", x, x)
    rhs = np.einsum("mki,mkj->mij", x, dxy)                      # (M, 3, 2)
    cnt = np.maximum(a_mat[:, 2, 2], 1.0)
    cov = a_mat[:, :2, :2] - np.einsum("mi,mj->mij", a_mat[:, :2, 2], a_mat[:, :2, 2]) / cnt[:, None, None]
    fine = (valid.sum(axis=1) >= 4) & (np.linalg.eigvalsh(cov)[:, 0] > 0.5)
    jac = np.zeros((len(which), 2, 2))
    if fine.any():
        sol = np.linalg.solve(a_mat[fine], rhs[fine])            # (m, 3, 2): rows du, dv, 1
        jac[fine] = np.transpose(sol[:, :2, :], (0, 2, 1))
    return jac, fine


def _grow(points: np.ndarray, lattice: str, ref: int, jac0: np.ndarray, pitch: float
          ) -> tuple[np.ndarray, np.ndarray]:
    """Lattice indices grown from detection ``ref`` (index (0, 0)) outwards (see the module's docstring).

    Args:
        points: ``(N, 2)`` detections, pixels.
        lattice: ``"hex"`` or ``"rect"``.
        ref: the starting detection.
        jac0: ``(2, 2)`` lattice Jacobian ``d(x, y) / d(u, v)`` at ``ref``.
        pitch: typical neighbour distance, pixels.

    Returns:
        ``(N,) bool`` assigned and ``(N, 2) int64`` indices relative to ``ref`` (meaningless where unassigned).
    """
    n = len(points)
    done = np.zeros(n, bool)
    idx = np.zeros((n, 2), np.int64)
    uv = np.zeros((n, 2))
    jac = np.zeros((n, 2, 2))
    done[ref] = True
    jac[ref] = jac0
    taken = _keys(idx[[ref]])
    while True:
        a = np.flatnonzero(done)
        u = np.flatnonzero(~done)
        if not len(u):
            break
        k = min(4, len(a))
        d, j = cKDTree(points[a]).query(points[u], k=k, distance_upper_bound=_GROW_REACH * pitch)
        d, j = d.reshape(len(u), k), j.reshape(len(u), k)
        valid = np.isfinite(d)
        near = valid[:, 0]
        if not near.any():
            break
        u, d, j, valid = u[near], d[near], j[near], valid[near]
        nb = a[np.minimum(j, len(a) - 1)]                        # (M, k)
        delta = points[u][:, None, :] - points[nb]
        pred = uv[nb] + np.linalg.solve(jac[nb], delta[..., None])[..., 0]
        wts = valid / np.maximum(d, 1e-9)
        mean = np.einsum("mk,mki->mi", wts, pred) / wts.sum(axis=1)[:, None]
        nid, nuv = _nearest_nodes(mean, lattice)
        dist = np.linalg.norm(mean - nuv, axis=1)
        agree = np.all(~valid | (np.linalg.norm(pred - nuv[:, None, :], axis=2) < _GROW_AGREE), axis=1)
        good = (dist < _GROW_TOL) & agree & ~np.isin(_keys(nid), taken)
        if not good.any():
            break
        u, nid, nuv, dist, nb = u[good], nid[good], nuv[good], dist[good], nb[good]
        first = _closest_per_node(nid, dist)
        u, nid, nuv, nb = u[first], nid[first], nuv[first], nb[first]
        done[u] = True
        idx[u] = nid
        uv[u] = nuv
        taken = np.concatenate([taken, _keys(nid)])
        local, fine = _local_jacobians(points, uv, done, u, pitch)
        jac[u] = np.where(fine[:, None, None], local, jac[nb[:, 0]])  # else: the nearest neighbour's
    return done, idx


def _assign_model(model: _Model, points: np.ndarray, lattice: str, tol: float, taken: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Nodes of ``points`` through the inverse lattice model: one per free node (the closest), within ``tol``.

    Returns:
        ``(N,) bool`` assigned and ``(N, 2) int64`` indices.
    """
    uv = _model_inverse(model, points)
    idx, nodes = _nearest_nodes(uv, lattice)
    dist = np.linalg.norm(uv - nodes, axis=1)
    ok = np.isfinite(dist) & (dist < tol) & ~np.isin(_keys(idx), taken)
    return ok & _closest_per_node(idx, np.where(ok, dist, np.inf)), idx


def _final_indices(idx_rel: np.ndarray, lattice: str, row_offset: int) -> np.ndarray:
    """Indices relative to the reference spot -> top detected row ``row_offset``, leftmost column 0."""
    r_rel, c_rel = idx_rel[:, 0], idx_rel[:, 1]
    r = r_rel - r_rel.min() + row_offset
    if lattice == "hex":
        u2 = 2 * c_rel + (r_rel % 2)                         # twice the ideal u, integer
        c2 = u2 - (r % 2)                                    # twice (u - (r % 2) / 2): all even or all odd
        c = (c2 - c2.min()) // 2
    else:
        c = c_rel - c_rel.min()
    return np.stack([r, c], axis=1).astype(np.int64)


def _clean_fit(points: np.ndarray, idx_rel: np.ndarray, ok: np.ndarray, lattice: str, shape: tuple[int, int],
               what: str = "spots") -> tuple[_Model, float]:
    """Fit the lattice model to ``points[ok]``, drop outliers from ``ok`` (in place), refit until none is dropped.

    An outlier lies a quarter pitch or more off its node, or farther from its fitted position than
    ``_OUTLIER_SIGMAS`` robust sigmas of the residuals (``median length / 1.1774``, a 2-D Gaussian's) and
    ``_OUTLIER_FLOOR_PX``: a detection disturbed by something (a sub-image cut by the edge of the lit area, a
    hot pixel on a spot) is dropped rather than bending the lattice.

    Returns:
        The last model and the residual length (pixels) beyond which a detection is an outlier.
    """
    n = len(points)
    for _ in range(10):
        uv_nodes = lattice_coordinates(idx_rel[ok], lattice)
        model, _, _ = _fit_model(uv_nodes, points[ok], shape)
        off = np.linalg.norm(_model_inverse(model, points[ok]) - uv_nodes, axis=1)    # pitches
        res = np.linalg.norm(points[ok] - _model_apply(model, uv_nodes), axis=1)     # pixels
        limit = max(_OUTLIER_SIGMAS * float(np.median(res)) / 1.1774, _OUTLIER_FLOOR_PX)
        bad = (off >= _MAX_RESIDUAL) | (res > limit)
        if not bad.any():
            break
        ok[np.flatnonzero(ok)[bad]] = False
        if ok.sum() < 4:
            raise NoSpotsError(f"only {int(ok.sum())} of {n} {what} fit a {lattice} lattice; "
                               "at least 4 are needed")
    return model, limit


def _fit_lattice(points: np.ndarray, lattice: str, shape: tuple[int, int], sigma: float,
                 expected_shape: tuple[int, int] | None, kind: str = "spots") -> LatticeFit:
    n = len(points)
    what = "spots" if kind == "spots" else "sub-images"
    tree = cKDTree(points)
    d, j = tree.query(points, k=min(7, n))
    pitch0 = float(np.median(d[:, 1]))
    if not pitch0 > 0:
        raise NoSpotsError(f"the {n} {what} do not form a lattice (coincident detections)")
    near = (d[:, 1:] > 0.7 * pitch0) & (d[:, 1:] < 1.3 * pitch0)
    vec = (points[j[:, 1:]] - points[:, None, :])[near]
    fold = 6 if lattice == "hex" else 4
    z = np.mean(np.exp(1j * fold * np.arctan2(vec[:, 1], vec[:, 0]))) if len(vec) else 0.0
    if abs(z) < 0.5:
        raise NoSpotsError(f"the {n} {what} do not form a {lattice} lattice (neighbour directions disagree with "
                           f"a {360 // fold}-degree symmetry)")
    theta = np.angle(z) / fold
    b_angle = theta + (math.pi / 3 if lattice == "hex" else math.pi / 2)
    basis = pitch0 * np.array([[math.cos(theta), math.cos(b_angle)], [math.sin(theta), math.sin(b_angle)]])
    # Reference: the spot nearest the middle of the detections among those with the most lattice neighbours
    # (not a stray detection).
    degree = near.sum(axis=1)
    well = np.flatnonzero(degree >= min(3, degree.max()))
    centre = np.median(points, axis=0)
    ref_i = int(well[np.argmin(np.linalg.norm(points[well] - centre, axis=1))])
    ref = points[ref_i]
    # Refine the two lattice vectors near the reference spot.
    local = np.linalg.norm(points - ref, axis=1) < 4.0 * pitch0
    lvec = (points[j[:, 1:]] - points[:, None, :])[near & local[:, None]]
    for col in range(2):
        e = basis[:, col]
        close = np.minimum(np.linalg.norm(lvec - e, axis=1), np.linalg.norm(lvec + e, axis=1)) < 0.3 * pitch0
        if close.any():
            v = lvec[close]
            v = np.where((v @ e)[:, None] < 0, -v, v)
            basis[:, col] = v.mean(axis=0)
    ideal_basis = np.array([[1.0, 0.5], [0.0, _SQRT3_2]]) if lattice == "hex" else np.eye(2)
    jac0 = basis @ np.linalg.inv(ideal_basis)
    if abs(np.linalg.det(jac0)) < 1e-9 * pitch0 * pitch0:
        raise NoSpotsError(f"the {n} {what} do not form a {lattice} lattice (degenerate lattice vectors)")
    # Indices: grow the lattice from the reference outwards, each node predicted by its assigned neighbours.
    ok, idx_rel = _grow(points, lattice, ref_i, jac0, pitch0)
    if ok.sum() < 4:
        raise NoSpotsError(f"only {int(ok.sum())} of {n} {what} fit a {lattice} lattice; at least 4 are needed")
    # Lattice model through the grown nodes, without the detections off it; then the detections the growth
    # did not reach (beyond gaps) through the model, and the model again.
    model, limit = _clean_fit(points, idx_rel, ok, lattice, shape, what)
    rest = np.flatnonzero(~ok)
    if len(rest):
        more, idx_more = _assign_model(model, points[rest], lattice, _MAX_RESIDUAL, _keys(idx_rel[ok]))
        more &= np.linalg.norm(points[rest] - _model_apply(model, lattice_coordinates(idx_more, lattice)),
                               axis=1) <= limit
        ok[rest[more]] = True
        idx_rel[rest[more]] = idx_more[more]
        if more.any():
            _clean_fit(points, idx_rel, ok, lattice, shape, what)
    kept, idx_rel = points[ok], idx_rel[ok]
    indices = _final_indices(idx_rel, lattice, 0)
    if expected_shape is not None:
        rows_e, cols_e = _check_shape(expected_shape)
        span = indices.max(axis=0) + 1
        if lattice == "hex" and span[1] > cols_e and span[0] < rows_e:
            shifted = _final_indices(idx_rel, lattice, 1)             # the top detected row is an odd row
            if np.all(shifted.max(axis=0) + 1 <= (rows_e, cols_e)):
                indices = shifted
        span = indices.max(axis=0) + 1
        if span[0] > rows_e or span[1] > cols_e:
            raise NoSpotsError(f"the {what} span {span[0]} rows x {span[1]} columns, more than the expected "
                               f"{rows_e} x {cols_e} array")
        expected_shape = (rows_e, cols_e)
    order = np.lexsort((indices[:, 1], indices[:, 0]))
    kept, indices = kept[order], indices[order]
    ideal = lattice_coordinates(indices, lattice)
    model, rms, rms_h = _fit_model(ideal, kept, shape)
    residuals = kept - _model_apply(model, ideal)
    rms = float(np.sqrt(np.mean(np.sum(residuals ** 2, axis=1))))
    pitch, rotation = _pitch_rotation(model, shape)
    return LatticeFit(lattice=lattice, centres=kept, indices=indices, homography=model.h, residuals=residuals,
                      rms_px=rms, pitch_px=pitch, rotation_deg=rotation,
                      origin=_model_apply(model, np.zeros((1, 2)))[0], image_shape=(int(shape[0]), int(shape[1])),
                      spot_sigma_px=float(sigma), rejected=int(n - len(kept)), expected_shape=expected_shape,
                      distortion=model.k, distortion_centre=model.centre, distortion_scale=model.scale,
                      homography_rms_px=rms if not np.any(model.k) else float(rms_h), kind=kind)


def _pitch_rotation(model: _Model, shape: tuple[int, int]) -> tuple[float, float]:
    """Row spacing (pixels) and row direction (degrees counter-clockwise on screen) at the image centre."""
    centre = np.array([[(shape[1] - 1) / 2.0, (shape[0] - 1) / 2.0]])
    uv = _model_inverse(model, centre)[0]
    eps = 1e-4
    d = (_model_apply(model, (uv + [eps, 0.0])[None]) - _model_apply(model, (uv - [eps, 0.0])[None]))[0] / (2 * eps)
    return float(math.hypot(d[0], d[1])), float(math.degrees(math.atan2(-d[1], d[0])))

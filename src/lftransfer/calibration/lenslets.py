"""Lenslet centres from an image of a collimated on-axis source through the lens array.

Every lenslet focuses the plane wave into one small spot at the image of its optical centre (see
``lftransfer.rig.sim.SimRig.capture_collimated``). :func:`find_lenslet_centres` finds those spots to a small
fraction of a pixel and fits the lattice to them (``lft calibrate lenslets IMAGE --lattice hex --out
centres.csv``):

1. background: the median of 16 or 32 pixel blocks, interpolated, is subtracted (follows vignetting and an
   uneven dark background); later passes leave the bright pixels of the previous one out, so that dense spots
   do not raise it. Hot pixels (a single pixel far above its 3 x 3 median) are replaced by that median.
   The noise is measured on what is left, without the spots, on the lower half of the distribution (the
   upper half where the dark background was clipped at zero);
2. spots: local maxima of the lightly smoothed image above 5 noise sigmas, above 10 % of the brightest spot
   within two pitches and above 5 % of the bright spots (95th percentile) anywhere (dim vignetted border spots
   are kept, noise maxima are not); spots whose centre lies
   within ``2.5 sigma`` (at least 2 px) of the image border are dropped (clipped spots);
3. sub-pixel centres: Gaussian-windowed centroid (the window's sigma is the spots' own, estimated from the
   brightest spots), iterated to its fixed point on the background-subtracted image, after subtracting each
   spot's local background (median of a ring around it);
4. lattice: pitch from nearest-neighbour distances, rotation from the neighbours' directions (modulo 60 deg
   for ``hex``, 90 deg for ``rect``), integer indices assigned from the centre outwards while a homography from
   the ideal lattice to the image is refined (the camera may view the array at a tilt), then a RANSAC
   homography, a least-squares one on its inliers, one more assignment and a final least-squares fit.
   Detections more than a quarter pitch from every lattice node are dropped.

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
from dataclasses import dataclass

import cv2
import numpy as np
from scipy.ndimage import median_filter
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
            :func:`lattice_coordinates`) to pixels, least-squares fit to all ``centres``.
        residuals: ``(N, 2) float64`` detected minus fitted lattice position, pixels.
        rms_px: RMS length of ``residuals``, pixels.
        pitch_px: lenslet spacing along a row at the image centre (from ``homography``), pixels.
        rotation_deg: direction of the rows at the image centre, degrees counter-clockwise as seen on screen
            (image y points down); the rows are the lattice direction closest to the image x axis, so it lies
            within about +-30 deg (hex) or +-45 deg (rect). For a camera that faces the array squarely it has
            the sign of ``LensArray.rotation``.
        origin: ``(2,) float64`` pixel position of lattice index ``(0, 0)`` (from ``homography``).
        image_shape: ``(H, W)`` of the image.
        spot_sigma_px: estimated standard deviation of the spots' blur, pixels.
        rejected: detections dropped by the lattice fit (off the lattice, or a second spot on one node).
        expected_shape: ``(rows, cols)`` of the array if it was given, else None.
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

    def predicted(self, indices: np.ndarray) -> np.ndarray:
        """Fitted lattice positions of lattice indices.

        Args:
            indices: ``(N, 2)`` integer ``(row, col)`` lattice indices (any, also of lenslets not detected).

        Returns:
            ``(N, 2) float64`` pixels (x, y) through ``homography``.
        """
        return _apply(self.homography, lattice_coordinates(indices, self.lattice))

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
        return "\n".join([
            f"lattice: {self.lattice}, {count}",
            f"pitch: {self.pitch_px:.3f} px along rows at the image centre; "
            f"rotation: {self.rotation_deg:+.3f} deg (counter-clockwise)",
            f"origin (row 0, col 0): ({ox:.3f}, {oy:.3f}) px; spot sigma {self.spot_sigma_px:.2f} px",
            f"homography fit residuals: RMS {self.rms_px:.4f} px, max {self.max_residual_px:.4f} px; "
            f"{self.rejected} detection(s) off the lattice dropped",
        ])


def find_lenslet_centres(image: np.ndarray, lattice: str, *,
                         expected_shape: tuple[int, int] | None = None) -> LatticeFit:
    """Find every lenslet's spot to sub-pixel accuracy and fit the lattice (see the module's docstring).

    Args:
        image: ``(H, W)`` grey image (float, any scale), or any array :func:`lftransfer.calibration.images.to_grey`
            takes (``uint8``/``uint16``, colour); bright spots on a dark background.
        lattice: ``"hex"`` or ``"rect"``.
        expected_shape: ``(rows, cols)`` of the lens array, if known: a fit spanning more rows or columns is an
            error, and for ``hex`` an odd top row (row 0 clipped off) is recognised and indexed as such.

    Returns:
        The fit; ``centres`` holds only lenslets whose spot is wholly inside the image (missing spots are absent).

    Raises:
        ValueError: ``lattice`` is neither ``"hex"`` nor ``"rect"``, or the image is not an image.
        NoSpotsError: no spots, fewer than 4, or no lattice of that kind through them.
    """
    _check_lattice(lattice)
    if expected_shape is not None:
        _check_shape(expected_shape)
    img = _as_grey(image)
    points, sigma = _detect_spots(img)
    if len(points) < 4:
        raise NoSpotsError(f"found {len(points)} lenslet spot(s); at least 4 are needed to fit a lattice")
    return _fit_lattice(points, lattice, img.shape, sigma, expected_shape)


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


def _nearest_nodes(uv: np.ndarray, lattice: str) -> tuple[np.ndarray, np.ndarray]:
    """Nearest lattice nodes of ideal coordinates: ``(N, 2) int64`` (row, col) and their ``(N, 2)`` (u, v)."""
    r = np.rint(uv[:, 1] / _ROW_STEP[lattice]).astype(np.int64)
    shift = 0.5 * (r % 2) if lattice == "hex" else 0.0
    c = np.rint(uv[:, 0] - shift).astype(np.int64)
    idx = np.stack([r, c], axis=1)
    return idx, lattice_coordinates(idx, lattice)


def _assign(h: np.ndarray, points: np.ndarray, lattice: str, tol: float
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Lattice nodes of ``points`` through the inverse of ``h``; one point per node (the closest), within ``tol``.

    Returns:
        ``(N,) bool`` inliers, ``(N, 2) int64`` indices and ``(N, 2)`` ideal node coordinates.
    """
    uv = _apply(np.linalg.inv(h), points)
    idx, nodes = _nearest_nodes(uv, lattice)
    dist = np.linalg.norm(uv - nodes, axis=1)
    ok = np.isfinite(dist) & (dist < tol)
    # one detection per node: the closest wins
    order = np.lexsort((dist, idx[:, 1], idx[:, 0]))
    first = np.ones(len(order), bool)
    first[1:] = np.any(idx[order][1:] != idx[order][:-1], axis=1)
    unique = np.zeros(len(points), bool)
    unique[order[first]] = True
    return ok & unique, idx, nodes


def _homography(nodes: np.ndarray, points: np.ndarray, ransac_px: float | None = None
                ) -> tuple[np.ndarray, np.ndarray]:
    """Homography ideal -> pixels (least squares, or RANSAC with threshold ``ransac_px``) and its inlier mask."""
    if len(nodes) < 4 or len(np.unique(nodes[:, 0])) < 2 or len(np.unique(nodes[:, 1])) < 2:
        raise NoSpotsError(f"the {len(nodes)} spots on the lattice do not span two rows and columns; "
                           "cannot fit a lattice")
    src, dst = nodes.astype(np.float64), points.astype(np.float64)
    if ransac_px is None:
        h, mask = cv2.findHomography(src, dst, 0)
    else:
        h, mask = cv2.findHomography(src, dst, cv2.RANSAC, ransac_px, maxIters=2000, confidence=0.999)
    if h is None or not np.all(np.isfinite(h)) or abs(np.linalg.det(h)) < 1e-12:
        raise NoSpotsError(f"could not fit a lattice homography to {len(nodes)} spots")
    inl = np.ones(len(nodes), bool) if mask is None else mask.ravel().astype(bool)
    return h / h[2, 2], inl


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


def _fit_lattice(points: np.ndarray, lattice: str, shape: tuple[int, int], sigma: float,
                 expected_shape: tuple[int, int] | None) -> LatticeFit:
    n = len(points)
    tree = cKDTree(points)
    d, j = tree.query(points, k=min(7, n))
    pitch0 = float(np.median(d[:, 1]))
    if not pitch0 > 0:
        raise NoSpotsError(f"the {n} spots do not form a lattice (coincident detections)")
    near = (d[:, 1:] > 0.7 * pitch0) & (d[:, 1:] < 1.3 * pitch0)
    vec = (points[j[:, 1:]] - points[:, None, :])[near]
    fold = 6 if lattice == "hex" else 4
    z = np.mean(np.exp(1j * fold * np.arctan2(vec[:, 1], vec[:, 0]))) if len(vec) else 0.0
    if abs(z) < 0.5:
        raise NoSpotsError(f"the {n} spots do not form a {lattice} lattice (neighbour directions disagree with "
                           f"a {360 // fold}-degree symmetry)")
    theta = np.angle(z) / fold
    b_angle = theta + (math.pi / 3 if lattice == "hex" else math.pi / 2)
    basis = pitch0 * np.array([[math.cos(theta), math.cos(b_angle)], [math.sin(theta), math.sin(b_angle)]])
    # Reference: the spot nearest the middle of the detections among those with the most lattice neighbours
    # (not a stray detection).
    degree = near.sum(axis=1)
    well = np.flatnonzero(degree >= min(3, degree.max()))
    centre = np.median(points, axis=0)
    ref = points[well[np.argmin(np.linalg.norm(points[well] - centre, axis=1))]]
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
    h = np.eye(3)
    h[:2, :2] = basis @ np.linalg.inv(ideal_basis)
    h[:2, 2] = ref
    # Grow the region from the centre, refining the homography as more spots are indexed.
    dist = np.linalg.norm(points - ref, axis=1)
    radius = 3.5 * pitch0
    while True:
        sel = dist <= radius
        ok, _, nodes = _assign(h, points[sel], lattice, 0.3)
        if ok.sum() >= 4:
            try:
                h, _ = _homography(nodes[ok], points[sel][ok])
            except NoSpotsError:
                if radius >= dist.max():
                    raise
        if radius >= dist.max():
            break
        radius *= 1.6
    ok, _, nodes = _assign(h, points, lattice, 0.35)
    if ok.sum() < 4:
        raise NoSpotsError(f"only {int(ok.sum())} of {n} spots fit a {lattice} lattice; at least 4 are needed")
    # RANSAC (robust to stray detections), least squares on its inliers, one more assignment, final fit.
    _, inl = _homography(nodes[ok], points[ok], ransac_px=max(0.15 * pitch0, 0.5))
    h, _ = _homography(nodes[ok][inl], points[ok][inl])
    ok, idx_rel, nodes = _assign(h, points, lattice, _MAX_RESIDUAL)
    if ok.sum() < 4:
        raise NoSpotsError(f"only {int(ok.sum())} of {n} spots fit a {lattice} lattice; at least 4 are needed")
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
            raise NoSpotsError(f"the spots span {span[0]} rows x {span[1]} columns, more than the expected "
                               f"{rows_e} x {cols_e} array")
        expected_shape = (rows_e, cols_e)
    order = np.lexsort((indices[:, 1], indices[:, 0]))
    kept, indices = kept[order], indices[order]
    ideal = lattice_coordinates(indices, lattice)
    h, _ = _homography(ideal, kept)
    residuals = kept - _apply(h, ideal)
    rms = float(np.sqrt(np.mean(np.sum(residuals ** 2, axis=1))))
    pitch, rotation = _pitch_rotation(h, shape)
    return LatticeFit(lattice=lattice, centres=kept, indices=indices, homography=h, residuals=residuals,
                      rms_px=rms, pitch_px=pitch, rotation_deg=rotation, origin=_apply(h, np.zeros((1, 2)))[0],
                      image_shape=(int(shape[0]), int(shape[1])), spot_sigma_px=float(sigma),
                      rejected=int(n - len(kept)), expected_shape=expected_shape)


def _pitch_rotation(h: np.ndarray, shape: tuple[int, int]) -> tuple[float, float]:
    """Row spacing (pixels) and row direction (degrees counter-clockwise on screen) at the image centre."""
    centre = np.array([[(shape[1] - 1) / 2.0, (shape[0] - 1) / 2.0]])
    u, v = _apply(np.linalg.inv(h), centre)[0]
    x, y = _apply(h, np.array([[u, v]]))[0]
    den = h[2, 0] * u + h[2, 1] * v + h[2, 2]
    dxdu = (h[0, 0] - x * h[2, 0]) / den
    dydu = (h[1, 0] - y * h[2, 0]) / den
    return float(math.hypot(dxdu, dydu)), float(math.degrees(math.atan2(-dydu, dxdu)))

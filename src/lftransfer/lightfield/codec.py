"""Precomputed resampling between a device image behind the lens array and a :class:`LightField` grid.

Both directions are a single ``cv2.remap`` with maps built once (docs/architecture.md, "The interface"):

- image -> light field (capture): each grid sample (k, u_j, v_i) reads the device pixel where its ray lands
  (:meth:`LensletDevice.ray_to_pixel`, so the lens distortion is applied);
- light field -> image (projection): each device pixel reads the grid at its own ray's (u, v)
  (:meth:`LensletDevice.pixel_to_ray`), the light field tiled as a ``(K * V, U)`` image.

For the device codecs (``devices.py``) the forward remap can also run as gather + interpolate
(:class:`_PatchSampler`), so that a per-pixel function of the raw image (the camera response) is evaluated
only on the pixels the map reads; the result is the same, bit for bit.
"""

from __future__ import annotations

import cv2
import numpy as np

from lftransfer.lightfield.lightfield import LightField
from lftransfer.optics.device import LensletDevice
from lftransfer.optics.lens_array import LensArray
from lftransfer.optics.geometry import apply_homography

__all__ = ["LensletCodec"]

_OUTSIDE = -1.0e4        # map coordinate far outside any source image: remap returns the border value 0
_CV_MAX = 32767          # cv2.remap needs source and destination sizes below SHRT_MAX
_MIN_WEIGHT = 1e-4       # inverse map: pixels whose valid interpolation weight is below this stay black
_CORNERS = ((0, 0), (1, 0), (0, 1), (1, 1))
_PULL_STEP = 0.5         # px per step when pulling a sample that landed off its lenslet back onto it
_MAX_PULL_STEPS = 64


def _bilinear_numpy(src: np.ndarray, mx: np.ndarray, my: np.ndarray) -> np.ndarray:
    """Bilinear gather with zero outside ``src`` (the fallback for images too large for ``cv2.remap``)."""
    h, w = src.shape[:2]
    x0, y0 = np.floor(mx).astype(np.int64), np.floor(my).astype(np.int64)
    tx, ty = (mx - x0).astype(np.float32), (my - y0).astype(np.float32)
    out = np.zeros(mx.shape + src.shape[2:], np.float32)
    for dy, wy in ((0, 1.0 - ty), (1, ty)):
        for dx, wx in ((0, 1.0 - tx), (1, tx)):
            xx, yy = x0 + dx, y0 + dy
            ok = (xx >= 0) & (xx < w) & (yy >= 0) & (yy < h)
            wgt = np.where(ok, wx * wy, 0.0).astype(np.float32)
            val = src[np.clip(yy, 0, h - 1), np.clip(xx, 0, w - 1)]
            out += (wgt[..., None] * val) if src.ndim == 3 else wgt * val
    return out


class _Remap:
    """One precomputed bilinear resampling ``dst[r, c] = src(map_y[r, c], map_x[r, c])``, zero outside."""

    def __init__(self, map_x: np.ndarray, map_y: np.ndarray, src_shape: tuple[int, int]) -> None:
        self.map_x = np.ascontiguousarray(map_x, dtype=np.float32)
        self.map_y = np.ascontiguousarray(map_y, dtype=np.float32)
        self.src_shape = src_shape
        self.use_cv = max(*src_shape, *self.map_x.shape) < _CV_MAX
        if self.use_cv:
            # fixed point: m1 = integer top-left pixel (x0, y0), m2 = 1/32-px fraction index (ty * 32 + tx)
            self._m1, self._m2 = cv2.convertMaps(self.map_x, self.map_y, cv2.CV_16SC2)

    def matrix(self):
        """This resampling as a ``(R * C, H * W)`` ``scipy.sparse.csr_matrix`` (one channel; row-major pixel
        indices): the same four taps and weights (``cv2.remap``'s 1/32-pixel fixed-point fractions where it is
        used), taps outside the source dropped, so that ``matrix() @ src`` is the resampling and its transpose
        scatters back."""
        from scipy.sparse import csr_matrix

        h, w = self.src_shape
        if self.use_cv:
            x0 = self._m1[..., 0].astype(np.int64).ravel()
            y0 = self._m1[..., 1].astype(np.int64).ravel()
            frac = self._m2.astype(np.int64).ravel()
            tx = (frac & 31).astype(np.float32) / np.float32(32)
            ty = (frac >> 5).astype(np.float32) / np.float32(32)
        else:
            mx, my = self.map_x.ravel().astype(np.float64), self.map_y.ravel().astype(np.float64)
            x0, y0 = np.floor(mx).astype(np.int64), np.floor(my).astype(np.int64)
            tx, ty = (mx - x0).astype(np.float32), (my - y0).astype(np.float32)
        rows = np.arange(x0.size)
        taps = [(x0, y0, (1 - tx) * (1 - ty)), (x0 + 1, y0, tx * (1 - ty)), (x0, y0 + 1, (1 - tx) * ty),
                (x0 + 1, y0 + 1, tx * ty)]
        r, c, v = [], [], []
        for x, y, weight in taps:
            inside = (x >= 0) & (x < w) & (y >= 0) & (y < h) & (weight != 0)
            r.append(rows[inside])
            c.append(y[inside] * w + x[inside])
            v.append(weight[inside])
        return csr_matrix((np.concatenate(v), (np.concatenate(r), np.concatenate(c))), shape=(x0.size, h * w),
                          dtype=np.float32)

    def __call__(self, src: np.ndarray) -> np.ndarray:
        src = np.ascontiguousarray(src, dtype=np.float32)
        if self.use_cv:
            out = cv2.remap(src, self._m1, self._m2, interpolation=cv2.INTER_LINEAR,
                            borderMode=cv2.BORDER_CONSTANT, borderValue=0)
            if src.ndim == 3 and out.ndim == 2:  # cv2 drops a trailing channel axis of length 1
                out = out[..., None]
            return out
        return _bilinear_numpy(src, self.map_x, self.map_y)


class _PatchSampler:
    """The forward remap split in two: gather the 2 x 2 source pixels it reads, then interpolate them.

    ``gather(src)`` copies, for every destination sample, the 2 x 2 block of source pixels that the bilinear
    remap reads (0 outside the source) into its own block of a small "patch" image (nearest-neighbour
    ``cv2.remap``, no arithmetic). ``interpolate(patch)`` then applies the same fixed-point bilinear weights as
    the full remap. For any per-pixel function f, ``interpolate(f(gather(src)))`` equals
    ``remap(f(src))`` exactly (when f(0-border) is the border value 0), at the cost of evaluating f on 4
    pixels per sample instead of on the whole source image.
    """

    def __init__(self, remap: _Remap) -> None:
        m1, m2 = remap._m1, remap._m2                       # (R, C, 2) int16 top-left pixels, (R, C) fractions
        R, C = m2.shape
        self.shape = (R, C)
        gather = np.empty((2 * R, 2 * C, 2), np.int16)     # patch pixel (2r + dy, 2c + dx) <- source pixel
        x0, y0 = m1[..., 0].astype(np.int32), m1[..., 1].astype(np.int32)
        for dy in (0, 1):
            for dx in (0, 1):
                # x0 + 1 is at most 32767 (source sizes are below it); outside coordinates stay outside
                gather[dy::2, dx::2, 0] = np.clip(x0 + dx, -_CV_MAX, _CV_MAX)
                gather[dy::2, dx::2, 1] = np.clip(y0 + dy, -_CV_MAX, _CV_MAX)
        self._gather = gather
        cc, rr = np.meshgrid(np.arange(C, dtype=np.int16) * 2, np.arange(R, dtype=np.int16) * 2)
        self._m1 = np.ascontiguousarray(np.stack([cc, rr], axis=-1))
        self._m2 = m2

    @staticmethod
    def fits(remap: _Remap) -> bool:
        """Whether the patch image of ``remap`` stays within ``cv2.remap``'s size limit."""
        return remap.use_cv and 2 * max(remap.map_x.shape) < _CV_MAX

    def gather(self, src: np.ndarray) -> np.ndarray:
        """``(2R, 2C[, ch])`` patch image of the source pixels read by the remap (border value 0).

        Args:
            src: Source image in a dtype that ``cv2.remap`` takes (uint8, uint16, int16, float32, float64).
        """
        out = cv2.remap(src, self._gather, None, interpolation=cv2.INTER_NEAREST,
                        borderMode=cv2.BORDER_CONSTANT, borderValue=0)
        if src.ndim == 3 and out.ndim == 2:
            out = out[..., None]
        return out

    def interpolate(self, patch: np.ndarray) -> np.ndarray:
        """``(R, C[, ch]) float32`` bilinear result from a float32 patch image (as the full remap would give)."""
        out = cv2.remap(patch, self._m1, self._m2, interpolation=cv2.INTER_LINEAR,
                        borderMode=cv2.BORDER_CONSTANT, borderValue=0)
        if patch.ndim == 3 and out.ndim == 2:
            out = out[..., None]
        return out


class LensletCodec:
    """Precomputed maps between a device image (H, W, 3) and a light field grid (K, V, U, 3).

    Attributes:
        array: The lens array.
        device: The camera or projector behind it.
        U, V: Angular grid size.
        map_x, map_y: ``(K * V, U) float32`` forward map: device pixel (col, row) of every grid sample.
        inv_map_x, inv_map_y: ``(H, W) float32`` inverse map into the light field tiled as a ``(K * V, U)``
            image: ``inv_map_x = i_frac``, ``inv_map_y = k * V + j_frac``; far outside where there is no data.
        pixel_lenslet: ``(H, W) int64`` lenslet seen by each device pixel, -1 for none.
        mask: ``(V, U) bool`` the light field's data mask (:meth:`LightField.mask`).
    """

    def __init__(self, array: LensArray, device: LensletDevice, U: int, V: int) -> None:
        """Build both maps.

        Args:
            array: The lens array.
            device: The device behind it (its ``distortion`` must have shape ``(K, 2)``).
            U: Samples along u (>= 1).
            V: Samples along v (>= 1).
        """
        U, V = int(U), int(V)
        if U < 1 or V < 1:
            raise ValueError(f"U and V must be positive, got U={U}, V={V}")
        if device.distortion.shape != (array.K, 2):
            raise ValueError(f"device distortion has shape {device.distortion.shape}, expected ({array.K}, 2)")
        self.array, self.device, self.U, self.V = array, device, U, V
        K, H, W = array.K, device.height, device.width
        grid = LightField.zeros(array, U, V)
        self.mask = grid.mask()
        # the mask as float32 per channel: multiplying by it is the bool multiply, bit for bit, ~8x faster
        self._mask3 = np.ascontiguousarray(np.repeat(self.mask[:, :, None], 3, axis=-1), dtype=np.float32)
        a = array.half_width

        # ---- inverse map: every device pixel -> fractional grid index
        cols, rows = np.meshgrid(np.arange(W, dtype=np.float64), np.arange(H, dtype=np.float64))
        px = np.stack([cols.ravel(), rows.ravel()], axis=-1)
        k, d = device.pixel_to_ray(array, px)
        self.pixel_lenslet = k.reshape(H, W)
        valid = k >= 0
        u = np.where(valid, d[:, 0] / np.where(valid, d[:, 2], 1.0), np.inf)
        v = np.where(valid, d[:, 1] / np.where(valid, d[:, 2], 1.0), np.inf)
        tol = 1e-9 * a
        valid &= (np.abs(u) <= a + tol) & (np.abs(v) <= a + tol)
        fi = np.clip((u + a) / (2.0 * a) * U - 0.5, 0.0, U - 1)
        fj = np.clip((v + a) / (2.0 * a) * V - 0.5, 0.0, V - 1)
        self._pixel_owner = np.where(valid, k, -1).reshape(H, W)   # lenslet whose grid data the pixel shows
        inv_x = np.where(valid, fi, _OUTSIDE)
        inv_y = np.where(valid, np.maximum(k, 0) * V + fj, _OUTSIDE)
        self.inv_map_x = inv_x.reshape(H, W).astype(np.float32)
        self.inv_map_y = inv_y.reshape(H, W).astype(np.float32)
        self._inverse = _Remap(self.inv_map_x, self.inv_map_y, (K * V, U))
        # Renormalise over data samples so that pixels near a cell border are not darkened by masked zeros.
        tiled_mask = np.broadcast_to(self.mask.astype(np.float32), (K, V, U)).reshape(K * V, U)
        norm = self._inverse(tiled_mask)
        self._inv_norm = np.where(norm > _MIN_WEIGHT, 1.0 / np.maximum(norm, _MIN_WEIGHT), 0.0).astype(np.float32)

        # ---- forward map: every grid sample -> device pixel
        kk = np.repeat(np.arange(K), V * U)
        dd = np.tile(grid.directions().reshape(-1, 3), (K, 1))
        fwd = device.ray_to_pixel(array, kk, dd)                      # (K*V*U, 2)
        fwd = self._avoid_crosstalk(fwd, kk)
        keep = np.tile(self.mask.ravel(), K) & np.all(np.isfinite(fwd), axis=1)
        fwd[~keep] = _OUTSIDE
        self.map_x = fwd[:, 0].reshape(K * V, U).astype(np.float32)
        self.map_y = fwd[:, 1].reshape(K * V, U).astype(np.float32)
        self._forward = _Remap(self.map_x, self.map_y, (H, W))
        self._patches: _PatchSampler | None = None
        self._inv_norm3: np.ndarray | None = None
        self._padded: tuple[np.ndarray, np.ndarray] | None = None

    def _footprint(self, x: np.ndarray, y: np.ndarray, k: np.ndarray):
        """Bilinear footprint of points: ownership flags and weights of the four surrounding pixels.

        A pixel is owned by lenslet k when it lies behind k and its ray is inside the angular grid.

        Args:
            x, y: ``(N,)`` pixel coordinates (finite).
            k: ``(N,)`` lenslet of each point.

        Returns:
            ``own (N, 4) bool``, ``weight (N, 4) float64``, ``x0, y0 (N,) int64`` (top-left corner).
        """
        H, W = self._pixel_owner.shape
        x0, y0 = np.floor(x).astype(np.int64), np.floor(y).astype(np.int64)
        tx, ty = x - x0, y - y0
        own = np.empty((len(x), 4), bool)
        weight = np.empty((len(x), 4))
        for c, (dx, dy) in enumerate(_CORNERS):
            xx, yy = x0 + dx, y0 + dy
            inside = (xx >= 0) & (xx < W) & (yy >= 0) & (yy < H)
            lens = np.where(inside, self._pixel_owner[np.clip(yy, 0, H - 1), np.clip(xx, 0, W - 1)], -1)
            own[:, c] = lens == k
            weight[:, c] = (tx if dx else 1.0 - tx) * (ty if dy else 1.0 - ty)
        return own, weight, x0, y0

    def _avoid_crosstalk(self, px: np.ndarray, k: np.ndarray) -> np.ndarray:
        """Keep forward samples on their own lenslet's pixels.

        A sample whose ray lands wholly off its lenslet's pixels (distortion can push border samples out of
        the cell) is pulled towards the lenslet's centre pixel until it touches one of them. A sample whose
        bilinear footprint (the four surrounding pixels) includes pixels not owned by its lenslet (another
        lenslet's, none, or rays outside the [-a, a]^2 grid) is then moved onto the centre of its own
        footprint pixel with the largest bilinear weight, so that light of a neighbour (from the far side of
        its angular range) does not leak in at cell borders. Moves are below one pixel except for the pulled
        samples.

        Args:
            px: ``(N, 2)`` pixel coordinates (col, row) of the samples (NaN allowed).
            k: ``(N,)`` their lenslets.

        Returns:
            ``(N, 2)`` adjusted pixel coordinates (NaN stays NaN).
        """
        px = px.copy()
        finite = np.flatnonzero(np.all(np.isfinite(px), axis=1))
        x, y, kf = px[finite, 0], px[finite, 1], k[finite]
        cx, cy = apply_homography(self.device.homography, self.array.centres[kf]).T
        lost = np.arange(len(x))
        for _ in range(_MAX_PULL_STEPS):
            own, _, _, _ = self._footprint(x[lost], y[lost], kf[lost])
            lost = lost[~np.any(own, axis=1)]
            if len(lost) == 0:
                break
            dx, dy = cx[lost] - x[lost], cy[lost] - y[lost]
            dist = np.hypot(dx, dy)
            step = np.minimum(_PULL_STEP, dist) / np.maximum(dist, 1e-12)
            x[lost] += step * dx
            y[lost] += step * dy
        own, weight, x0, y0 = self._footprint(x, y, kf)
        fix = ~np.all(own | (weight <= 0), axis=1) & np.any(own, axis=1)
        best = np.argmax(np.where(own, weight + 1.0, 0.0), axis=1)
        offs = np.array(_CORNERS)
        x = np.where(fix, x0 + offs[best, 0], x)
        y = np.where(fix, y0 + offs[best, 1], y)
        px[finite, 0], px[finite, 1] = x, y
        return px

    # ------------------------------------------------------------ fast paths for the device codecs
    @property
    def patch_sampler(self) -> _PatchSampler | None:
        """The forward map as gather + interpolate (:class:`_PatchSampler`), None when images are too large."""
        if self._patches is None and _PatchSampler.fits(self._forward):
            self._patches = _PatchSampler(self._forward)
        return self._patches

    def patches_to_lightfield(self, patch: np.ndarray) -> LightField:
        """Finish :meth:`image_to_lightfield` from ``f(patch_sampler.gather(image))`` (float32, 3 channels).

        Equals ``image_to_lightfield(f(image))`` for any per-pixel f with ``f(0) = 0``. Masked samples read
        nothing (their map lies far outside the image, so the remap gives its border value 0 there): the
        masking multiply of :meth:`image_to_lightfield` would not change them and is left out.
        """
        out = self.patch_sampler.interpolate(np.ascontiguousarray(patch, dtype=np.float32))
        return LightField(out.reshape(self.array.K, self.V, self.U, 3), self.array)

    def _padded_inverse_maps(self) -> tuple[np.ndarray, np.ndarray] | None:
        """Fixed-point inverse maps into the tiled light field padded by 2 zero rows and columns.

        Pixels without data read the zero pad instead of lying far outside the source: the same values (0),
        but ``cv2.remap`` keeps every pixel on its fast inside path (about a third faster). Pixels with data
        keep their map, and whatever neighbour they read outside the tiled grid (with weight 0) is 0 in both.
        """
        if self._padded is None and self._inverse.use_cv:
            rows, cols = self.array.K * self.V + 2, self.U + 2
            if max(rows, cols) < _CV_MAX:
                outside = self.inv_map_x < -1.0
                mx = np.where(outside, np.float32(self.U + 0.5), self.inv_map_x)
                my = np.where(outside, np.float32(rows - 1.5), self.inv_map_y)
                self._padded = cv2.convertMaps(mx, my, cv2.CV_16SC2)
        return self._padded

    def lightfield_to_unnormalised(self, lf: LightField) -> np.ndarray:
        """:meth:`lightfield_to_image` without the final renormalisation: ``(H, W, 3) float32`` remap result.

        ``lightfield_to_image(lf) == lightfield_to_unnormalised(lf) * inv_norm3`` (see :attr:`inv_norm3`).
        """
        self._check_lightfield(lf)
        K, V, U = self.array.K, self.V, self.U
        maps = self._padded_inverse_maps()
        if maps is None:
            return self._inverse(np.multiply(lf.data, self._mask3).reshape(K * V, U, 3))
        src = np.empty((K * V + 2, U + 2, 3), np.float32)
        src[K * V:] = 0.0
        src[:K * V, U:] = 0.0
        np.multiply(lf.data, self._mask3, out=src[:K * V].reshape(K, V, U + 2, 3)[:, :, :U])
        return cv2.remap(src, maps[0], maps[1], interpolation=cv2.INTER_LINEAR,
                         borderMode=cv2.BORDER_CONSTANT, borderValue=0)

    @property
    def inv_norm3(self) -> np.ndarray:
        """``(H, W, 3) float32`` renormalisation factor of :meth:`lightfield_to_image`, per channel (contiguous)."""
        if self._inv_norm3 is None:
            self._inv_norm3 = np.ascontiguousarray(np.repeat(self._inv_norm[..., None], 3, axis=-1))
        return self._inv_norm3

    def _check_lightfield(self, lf: LightField) -> None:
        if not isinstance(lf, LightField):
            raise ValueError(f"expected a LightField, got {type(lf).__name__}")
        if lf.array != self.array:
            raise ValueError("the light field belongs to a different lens array than the codec")
        expected = (self.array.K, self.V, self.U, 3)
        if lf.data.shape != expected:
            raise ValueError(f"light field has shape {lf.data.shape}, expected {expected}")

    def image_to_lightfield(self, image: np.ndarray) -> LightField:
        """Resample a device image onto the light field grid (bilinear; masked samples are 0).

        Args:
            image: ``(H, W, 3)`` float image of the device (e.g. linear radiance).

        Returns:
            LightField ``(K, V, U, 3) float32``.
        """
        image = np.asarray(image)
        expected = (self.device.height, self.device.width, 3)
        if image.shape != expected:
            raise ValueError(f"image has shape {image.shape}, expected {expected}")
        if not np.issubdtype(image.dtype, np.floating):
            raise ValueError(f"image must be a float array (linear values), got dtype {image.dtype}")
        out = self._forward(image).reshape(self.array.K, self.V, self.U, 3)
        out *= self._mask3
        return LightField(out, self.array)

    def image_to_lightfield_matrix(self):
        """:meth:`image_to_lightfield` of one channel as a ``(K * V * U, H * W)`` ``scipy.sparse.csr_matrix`` (the
        same taps and weights, masked samples 0; light field entries and pixels in row-major order): linear
        algebra over device images, its transpose scattering a light field back onto the pixels."""
        from scipy.sparse import diags

        keep = np.tile(self.mask.ravel(), self.array.K).astype(np.float32)
        return (diags(keep) @ self._forward.matrix()).tocsr()

    def lightfield_to_image(self, lf: LightField) -> np.ndarray:
        """Resample a light field onto the device's pixels (bilinear over data samples, 0 off the lenslets).

        Args:
            lf: LightField ``(K, V, U, 3)`` on this codec's array and grid.

        Returns:
            ``(H, W, 3) float32`` device image.
        """
        img = self.lightfield_to_unnormalised(lf)
        img *= self._inv_norm[..., None]
        return img

"""The device boundary: integer camera/projector images <-> linear-radiance light fields.

- :class:`LightFieldDecoder`: raw LF camera image (uint16 codes) -> :class:`LightField` of radiance.
- :class:`LightFieldEncoder`: :class:`LightField` of radiance -> projector image (uint8/uint16 codes).

Both are on the interactive transfer loop, so they avoid float work per device pixel where they can, with
results equal bit for bit to the plain float formulas in their docstrings (tests/lightfield/test_codec_fast.py):

- decode: the response is inverted through a table over all codes (gain folded in when there is no
  vignetting), only for the 2 x 2 pixels each light field sample reads (:class:`~.codec._PatchSampler`);
- encode: the renormalised remap result goes through :class:`_Quantiser`, an exact table of the quantiser
  ``round(levels * encode(clip(L / max_radiance, 0, 1)))`` indexed by the float's bit pattern. A projector with
  colour cross-talk or a black level first maps radiance to per-channel linear drive with one affine 3 x 4
  ``cv2.transform`` (``x = C^-1 (L / max_radiance - black_level)``) and then quantises that with the table of
  the same projector at ``max_radiance = 1``.

The table work per pixel runs in row blocks on a few threads (:data:`CODEC_THREADS`; numpy's gathers release the
GIL, and OpenCV's remaps use their own threads), each block writing its own rows: the result does not depend on
the split.
"""

from __future__ import annotations

import math
import os
import sys
import threading
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field, replace
from typing import Callable

import cv2
import numpy as np

from lftransfer.lightfield.codec import LensletCodec
from lftransfer.lightfield.lightfield import LightField
from lftransfer.lightfield.response import ResponseCurve
from lftransfer.optics.device import LensletDevice
from lftransfer.optics.lens_array import LensArray

__all__ = ["CameraModel", "ProjectorModel", "LightFieldDecoder", "LightFieldEncoder", "ProjectorDrive"]


def _check_bits(bits: int, name: str) -> int:
    if isinstance(bits, bool) or not isinstance(bits, (int, np.integer)) or not 1 <= bits <= 16:
        raise ValueError(f"{name}.bits must be an integer in [1, 16], got {bits!r}")
    return int(bits)


def _check_codes(image: np.ndarray, device: LensletDevice, what: str) -> np.ndarray:
    image = np.asarray(image)
    expected = (device.height, device.width, 3)
    if image.shape != expected:
        raise ValueError(f"{what} has shape {image.shape}, expected {expected}")
    if not np.issubdtype(image.dtype, np.integer):
        raise ValueError(f"{what} must hold integer codes (uint8/uint16), got dtype {image.dtype}")
    return image


def _as_cv_codes(codes: np.ndarray, levels: int) -> np.ndarray:
    """Integer codes in a dtype ``cv2.remap`` and the lookup tables take (uint8/uint16), same decoded values.

    Codes outside ``[0, levels]`` decode like the nearest end of the range, so other integer dtypes are
    clipped to it first.
    """
    if codes.dtype not in (np.uint8, np.uint16):
        codes = np.clip(codes.astype(np.int64, copy=False), 0, levels).astype(np.uint16)
    return np.ascontiguousarray(codes)


def _lookup(tables: np.ndarray, codes: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """``tables[c][codes[..., c]]`` per channel; ``tables`` is ``(1, n)`` (shared by the channels) or ``(3, n)``.

    ``codes`` must be below n (uint16 codes with n = 65536); mode="wrap" then changes nothing and spares
    numpy's bounds-checking buffer. Each channel gathers through a contiguous index (through the strided
    channel of one index array numpy gathers about twice as slowly).

    Args:
        tables: (1 or 3, n) values per code.
        codes: (H, W, 3) integer codes.
        out: where to write them (the shape of ``codes``, the tables' dtype), or None: a new array.
    """
    if len(tables) == 1:
        return np.take(tables[0], codes.astype(np.intp), out=out, mode="wrap")
    out = np.empty(codes.shape, tables.dtype) if out is None else out
    for c in range(3):
        out[..., c] = np.take(tables[c], codes[..., c].astype(np.intp), mode="wrap")
    return out


#: Threads that share the per-pixel table work of the codecs (numpy's gathers release the GIL) in row blocks.
CODEC_THREADS = max(1, min(os.cpu_count() or 1, 4))
_MIN_BLOCK_VALUES = 1 << 17                         # below this many values a block is not worth a thread
_pool: ThreadPoolExecutor | None = None
_pool_lock = threading.Lock()


def _forget_pool() -> None:
    global _pool
    _pool = None                                    # a forked child has none of the parent's threads


os.register_at_fork(after_in_child=_forget_pool)


def _in_row_blocks(work: Callable[[slice], None], rows: int, values_per_row: int) -> None:
    """Run ``work(rows_slice)`` over consecutive row blocks covering ``range(rows)``, on up to
    :data:`CODEC_THREADS` threads (each block writes its own rows of the output: the result does not depend on the
    split)."""
    global _pool
    blocks = int(min(CODEC_THREADS, max(1, rows * values_per_row // _MIN_BLOCK_VALUES), rows))
    if blocks <= 1:
        work(slice(0, rows))
        return
    with _pool_lock:
        if _pool is None:
            _pool = ThreadPoolExecutor(CODEC_THREADS, thread_name_prefix="lft-codec")
    edges = np.linspace(0, rows, blocks + 1).astype(int)
    for done in [_pool.submit(work, slice(a, b)) for a, b in zip(edges[:-1], edges[1:])]:
        done.result()


class _LinearCodes:
    """Exact arithmetic for a linear response (gamma = 1): ``float32(min(n, levels)) / levels * gain``.

    This is the decode table's entry for every code n bit for bit (``x ** 1 = x``, the divide and multiply are
    correctly rounded float32 operations) but costs a conversion instead of a gather. :meth:`build` checks
    that equality over all 65536 codes and gives None where it does not hold.
    """

    def __init__(self, levels: int, gain: np.float32) -> None:
        self.levels, self.gain = levels, np.float32(gain)

    @classmethod
    def build(cls, camera: "CameraModel", table: np.ndarray, gain: np.float32) -> "_LinearCodes | None":
        if not (camera.response.uniform and camera.response.gamma[0] == 1.0 and len(table) == 1):
            return None
        lin = cls(camera.levels, gain)
        return lin if np.array_equal(lin(np.arange(65536, dtype=np.uint16)), table[0]) else None

    def __call__(self, codes: np.ndarray) -> np.ndarray:
        codes = np.minimum(codes, np.uint16(self.levels))     # uint16 codes; above levels decode as levels
        x = codes.astype(np.float32)
        x /= np.float32(self.levels)
        x *= self.gain
        return x


def _encode_float(projector: "ProjectorModel", img: np.ndarray) -> np.ndarray:
    """The reference projector quantiser: float32 radiance -> codes (float32, rounded), see LightFieldEncoder."""
    linear = np.clip(img / np.float32(projector.max_radiance), 0.0, 1.0)
    code = projector.response.encode(linear)
    return np.round(code * np.float32(projector.levels))


_F32_INF_BITS = 0x7F800000   # bit pattern of +inf: positive finite float32s lie below it
_LITTLE_ENDIAN = sys.byteorder == "little"


class _Quantiser:
    """Exact lookup-table version of :func:`_encode_float` for float32 images.

    The map x -> code of :func:`_encode_float` is a non-decreasing step function of the float32 x, so it is
    fixed by the codes at the bin edges and the x where it steps. Bins are ranges of float32 bit patterns
    (``bits >> shift``, i.e. exponent and the top mantissa bits: relative width ``2^(shift - 23)``, which suits
    a power law). ``shift`` is chosen so that no bin holds more than one step; then
    ``code(x) = low[bin] + (x >= step[bin])`` with ``step`` NaN (never reached) in bins without a step. The
    steps are found by bisection on the reference function itself, so the table reproduces it bit for bit
    (negative values and -0 give 0, values above ``max_radiance`` and +inf the top code).
    """

    def __init__(self, low: np.ndarray, step: np.ndarray, shift: int) -> None:
        self.low, self.step, self.shift = low, step, shift

    @classmethod
    def build(cls, projector: "ProjectorModel", shifts=(16, 15, 14, 13, 12)) -> "_Quantiser | None":
        """The table for a projector, with the coarsest bins that work; None if no shift in ``shifts`` does."""
        channels = 1 if projector.response.uniform else 3
        for shift in shifts:
            with np.errstate(over="ignore", invalid="ignore"):   # huge floats / max_radiance overflow to inf
                table = cls._tables(projector, shift, channels)
            if table is not None:
                return cls(*table, shift)
        return None

    @staticmethod
    def _tables(projector: "ProjectorModel", shift: int, channels: int):
        def codes(bits: np.ndarray) -> np.ndarray:        # (N, 3) uint32 bit patterns -> (N, 3) int64 codes
            x = np.ascontiguousarray(bits, dtype=np.uint32).view(np.float32)
            return _encode_float(projector, x).astype(np.int64)

        n_pos = _F32_INF_BITS >> shift                      # bins of positive finite floats
        lo_bits = np.repeat((np.arange(n_pos, dtype=np.uint32) << np.uint32(shift))[:, None], 3, axis=1)
        hi_bits = lo_bits + np.uint32((1 << shift) - 1)
        lo, hi = codes(lo_bits), codes(hi_bits)
        if np.any(hi - lo > 1) or np.any(hi < lo):
            return None
        step = np.full((n_pos, 3), np.nan, np.float32)
        rows = np.flatnonzero(np.any(hi > lo, axis=1))
        a, b = lo_bits[rows].astype(np.int64), hi_bits[rows].astype(np.int64)   # codes(a) = lo, codes(b) = hi
        target = hi[rows]
        for _ in range(shift + 1):
            mid = (a + b) // 2
            up = codes(mid) >= target
            b, a = np.where(up, mid, b), np.where(up, a, mid)
        found = (hi[rows] > lo[rows])
        step_rows = b.astype(np.uint32).view(np.float32)
        step[rows] = np.where(found, step_rows, np.nan)
        n_all = 1 << (32 - shift)
        low = np.zeros((n_all, 3), np.int64)                # negative floats (sign bit set) -> code 0
        low[:n_pos] = lo
        low[n_pos:n_all // 2] = projector.levels            # +inf and NaN -> top code
        full_step = np.full((n_all, 3), np.nan, np.float32)
        full_step[:n_pos] = step
        low = np.ascontiguousarray(low[:, :channels].T.astype(projector.dtype))
        full_step = np.ascontiguousarray(full_step[:, :channels].T)
        return low, full_step

    def __call__(self, y: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """Codes of a C-contiguous ``(H, W, 3) float32`` image (into ``out`` if given)."""
        if self.shift == 16 and _LITTLE_ENDIAN:
            high = y.view(np.uint16)[..., 1::2]             # the high 16 bits of every float, no arithmetic
        else:
            high = y.view(np.uint32) >> np.uint32(self.shift)
        # every index is below the table size 2^(32 - shift): mode="wrap" changes nothing, skips the buffer
        if len(self.low) == 1:
            idx = high.astype(np.intp)                      # once, not inside each np.take
            code = np.take(self.low[0], idx, out=out, mode="wrap")
            code += y >= np.take(self.step[0], idx, mode="wrap")
            return code
        code = np.empty(y.shape, self.low.dtype) if out is None else out
        for c in range(3):                                  # a contiguous index per channel (see _lookup)
            idx = high[..., c].astype(np.intp)
            code[..., c] = np.take(self.low[c], idx, mode="wrap") + (y[..., c] >= np.take(self.step[c], idx,
                                                                                          mode="wrap"))
        return code


@dataclass(frozen=True, eq=False)
class CameraModel:
    """The LF camera behind the array: geometry, bit depth, response, exposure and vignetting.

    Attributes:
        device: Pixel <-> ray geometry.
        bits: Bits per raw code value.
        response: Linear signal <-> normalised code value.
        exposure: Normalised linear signal per unit radiance (signal = exposure * L * vignetting), sr m^2 W^-1.
        vignetting: ``(H, W) float32`` relative sensitivity per pixel, or None (= 1).
    """

    device: LensletDevice
    bits: int = 12
    response: ResponseCurve = field(default_factory=ResponseCurve)
    exposure: float = 1.0
    vignetting: np.ndarray | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "bits", _check_bits(self.bits, "CameraModel"))
        if not (np.isfinite(self.exposure) and self.exposure > 0):
            raise ValueError(f"exposure must be positive, got {self.exposure!r}")
        object.__setattr__(self, "exposure", float(self.exposure))
        if self.vignetting is not None:
            vig = np.asarray(self.vignetting, dtype=np.float32)
            expected = (self.device.height, self.device.width)
            if vig.shape != expected:
                raise ValueError(f"vignetting has shape {vig.shape}, expected {expected}")
            if np.any(vig < 0) or not np.all(np.isfinite(vig)):
                raise ValueError("vignetting must be finite and non-negative")
            object.__setattr__(self, "vignetting", vig)

    @property
    def levels(self) -> int:
        """Largest code value, ``2^bits - 1``."""
        return 2**self.bits - 1

    def expose(self, radiance_image: np.ndarray, noise: Callable[[np.ndarray], np.ndarray] | None = None) -> np.ndarray:
        """The forward model of the camera: radiance per pixel -> raw codes.

        ``signal = exposure * L * vignetting``, then ``noise(signal)`` if given, clipped to [0, 1], through
        ``response.encode``, quantised.

        Args:
            radiance_image: ``(H, W, 3)`` float radiance, W m^-2 sr^-1.
            noise: optional sensor noise model, normalised signal -> noisy normalised signal.

        Returns:
            ``(H, W, 3) uint16`` raw codes.
        """
        img = np.asarray(radiance_image)
        expected = (self.device.height, self.device.width, 3)
        if img.shape != expected:
            raise ValueError(f"radiance image has shape {img.shape}, expected {expected}")
        signal = self.exposure * img.astype(np.float64)
        if self.vignetting is not None:
            signal = signal * self.vignetting[..., None]
        if noise is not None:
            signal = noise(signal)
        code = self.response.encode(np.clip(signal, 0.0, 1.0))
        return np.round(code * self.levels).astype(np.uint16)


@dataclass(frozen=True, eq=False)
class ProjectorModel:
    """The projector behind the array: geometry, bit depth, response, brightness, colour mixing and black level.

    A pixel with codes ``n`` (RGB) makes its lenslet emit, per scene/camera RGB channel,
    ``L = max_radiance * (black_level + cross_talk @ response.decode(n / levels))``.

    Attributes:
        device: Pixel <-> ray geometry.
        bits: Bits per code value (8 -> uint8 images, more -> uint16).
        response: Linear drive <-> normalised code value, per projector channel.
        max_radiance: Radiance a full-code pixel makes its lenslet emit (without cross-talk and black level:
            exactly; otherwise the scale of both), W m^-2 sr^-1.
        cross_talk: ``(3, 3)`` matrix C: emitted RGB = C @ per-channel linear drive (column j: what projector
            channel j emits in each RGB channel); None means the identity. Must be finite and invertible.
        black_level: Light emitted at code 0, per RGB channel, as a fraction of ``max_radiance``, each in
            [0, 0.2).
    """

    device: LensletDevice
    bits: int = 8
    response: ResponseCurve = field(default_factory=ResponseCurve)
    max_radiance: float = 1.0
    cross_talk: np.ndarray | None = None
    black_level: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        object.__setattr__(self, "bits", _check_bits(self.bits, "ProjectorModel"))
        if not (np.isfinite(self.max_radiance) and self.max_radiance > 0):
            raise ValueError(f"max_radiance must be positive, got {self.max_radiance!r}")
        object.__setattr__(self, "max_radiance", float(self.max_radiance))
        if self.cross_talk is not None:
            try:
                c = np.array(self.cross_talk, dtype=np.float64)
            except (TypeError, ValueError) as exc:
                raise ValueError(f"cross_talk must be a (3, 3) matrix of numbers, got {self.cross_talk!r}") from exc
            if c.shape != (3, 3):
                raise ValueError(f"cross_talk must have shape (3, 3), got {c.shape}")
            if not np.all(np.isfinite(c)):
                raise ValueError("cross_talk must be finite")
            if np.linalg.cond(c) > 1e6:
                raise ValueError(f"cross_talk must be invertible, got {c.tolist()} "
                                 f"(condition number {np.linalg.cond(c):.3g})")
            c.setflags(write=False)
            object.__setattr__(self, "cross_talk", c)
        try:
            black = tuple(float(b) for b in self.black_level)
        except (TypeError, ValueError) as exc:
            raise ValueError(f"black_level must be three numbers, got {self.black_level!r}") from exc
        if len(black) != 3 or not all(math.isfinite(b) and 0.0 <= b < 0.2 for b in black):
            raise ValueError(f"black_level must be three numbers in [0, 0.2), got {self.black_level!r}")
        object.__setattr__(self, "black_level", black)

    @property
    def levels(self) -> int:
        """Largest code value, ``2^bits - 1``."""
        return 2**self.bits - 1

    @property
    def dtype(self) -> type:
        """Integer dtype of projector images: uint8 up to 8 bits, else uint16."""
        return np.uint8 if self.bits <= 8 else np.uint16

    @property
    def cross_talk_matrix(self) -> np.ndarray:
        """The ``(3, 3)`` cross-talk matrix, the identity where :attr:`cross_talk` is None."""
        return np.eye(3) if self.cross_talk is None else np.array(self.cross_talk)

    @property
    def mixes_colours(self) -> bool:
        """Whether emission is more than ``max_radiance * response.decode(code)`` (cross-talk or black level)."""
        identity = self.cross_talk is None or np.array_equal(self.cross_talk, np.eye(3))
        return not identity or any(b != 0.0 for b in self.black_level)

    def drive_affine(self) -> np.ndarray:
        """``(3, 4)`` affine map radiance -> linear drive, ``x = C^-1 (L / max_radiance - black_level)``."""
        inv = np.linalg.inv(self.cross_talk_matrix)
        return np.concatenate([inv / self.max_radiance, -(inv @ np.asarray(self.black_level))[:, None]], axis=1)

    def emit(self, linear: np.ndarray) -> np.ndarray:
        """Linear drive per projector channel ``(..., 3)`` -> emitted radiance (float32), the forward model."""
        linear = np.asarray(linear, dtype=np.float32)
        if not self.mixes_colours:
            return (linear * np.float32(self.max_radiance)).astype(np.float32, copy=False)
        m = np.concatenate([self.cross_talk_matrix, np.asarray(self.black_level)[:, None]], axis=1)
        m = (m * self.max_radiance).astype(np.float32)
        flat = np.ascontiguousarray(linear.reshape(-1, 1, 3))
        return cv2.transform(flat, m).reshape(linear.shape)


class LightFieldDecoder:
    """Raw LF camera image -> LightField of radiance (response, exposure, vignetting, then the codec)."""

    def __init__(self, array: LensArray, camera: CameraModel, U: int, V: int) -> None:
        """Precompute the codec.

        Args:
            array: The lens array.
            camera: The LF camera model.
            U: Samples along u.
            V: Samples along v.
        """
        self.array, self.camera = array, camera
        self.codec = LensletCodec(array, camera.device, U, V)
        vig = np.ones((camera.device.height, camera.device.width), np.float32) \
            if camera.vignetting is None else camera.vignetting
        gain = camera.exposure * vig.astype(np.float64)
        self._inv_gain = np.where(gain > 0, 1.0 / np.where(gain > 0, gain, 1.0), 0.0).astype(np.float32)
        # response inversion as a table over all uint16 codes; with no vignetting the (uniform) gain is folded
        # in: float32(table * g) is exactly the product the per-pixel path forms
        table = camera.response.decode_table(camera.levels)
        table = table[:1] if camera.response.uniform else table
        self._uniform_gain = camera.vignetting is None
        if self._uniform_gain:
            table = table * self._inv_gain[0, 0]
        self._table = np.ascontiguousarray(table, dtype=np.float32)
        self._linear = _LinearCodes.build(camera, self._table, self._inv_gain[0, 0]) if self._uniform_gain else None
        self._patches = self.codec.patch_sampler          # None where the images are too large for cv2.remap
        self._patch_gain = None
        if self._patches is not None and not self._uniform_gain:
            # per channel: a multiply broadcast over a last axis of 1 runs several times slower
            self._patch_gain = np.ascontiguousarray(np.repeat(self._patches.gather(self._inv_gain)[..., None], 3, -1))

    def radiance_image(self, raw: np.ndarray) -> np.ndarray:
        """Raw codes -> per-pixel radiance, ``decode(raw / (2^bits - 1)) / (exposure * vignetting)``.

        Args:
            raw: ``(H, W, 3)`` integer camera codes.

        Returns:
            ``(H, W, 3) float32`` radiance, W m^-2 sr^-1 (0 where vignetting is 0).
        """
        raw = _check_codes(raw, self.camera.device, "raw camera image")
        codes = _as_cv_codes(raw, self.camera.levels)
        radiance = _lookup(self._table, codes) if self._linear is None else self._linear(codes)
        if not self._uniform_gain:
            radiance *= self._inv_gain[..., None]
        return radiance

    def __call__(self, raw: np.ndarray) -> LightField:
        """Decode a raw camera image.

        Args:
            raw: ``(H, W, 3) uint16`` camera codes.

        Returns:
            LightField ``(K, V, U, 3) float32`` radiance.
        """
        if self._patches is None:
            return self.codec.image_to_lightfield(self.radiance_image(raw))
        # response and gain only on the pixels the codec's bilinear map reads (4 per sample), then the same
        # interpolation: equal to image_to_lightfield(radiance_image(raw)), without touching the other pixels
        raw = _check_codes(raw, self.camera.device, "raw camera image")
        codes = self._patches.gather(_as_cv_codes(raw, self.camera.levels))
        patch = np.empty(codes.shape, np.float32)

        def decode_rows(rows: slice) -> None:
            if self._linear is None:
                _lookup(self._table, codes[rows], out=patch[rows])
            else:
                patch[rows] = self._linear(codes[rows])
            if self._patch_gain is not None:
                patch[rows] *= self._patch_gain[rows]

        _in_row_blocks(decode_rows, codes.shape[0], codes[0].size)
        return self.codec.patches_to_lightfield(patch)

    def expose(self, radiance_image: np.ndarray) -> np.ndarray:
        """The noiseless forward model of the camera (see :meth:`CameraModel.expose`)."""
        return self.camera.expose(radiance_image)


class LightFieldEncoder:
    """LightField of radiance -> projector image (codec, brightness, inverse response, quantisation)."""

    def __init__(self, array: LensArray, projector: ProjectorModel, U: int, V: int, *,
                 above_black: bool = False) -> None:
        """Precompute the codec.

        Args:
            array: The lens array.
            projector: The projector model.
            U: Samples along u.
            V: Samples along v.
            above_black: the light field is light to add to what the projector emits at code 0 (its black
                level), not the whole radiance to emit: ``x = C^-1 L / max_radiance``. Light field transfer
                measures every projection against a frame with the projector black, so this is the light it
                means; encoding it as the whole radiance takes the black level off every entry (on Fig. 4's
                rig, whose black level is up to 1 % of the projector's maximum, 4 to 8 % of the light projected
                and every entry below the black level).
        """
        self.array, self.projector = array, projector
        self.above_black = above_black
        self.codec = LensletCodec(array, projector.device, U, V)
        # With cross-talk or a black level, radiance becomes linear drive through one affine transform; the
        # drive is then quantised like radiance of a plain projector with max_radiance = 1.
        self._affine: np.ndarray | None = None
        self._quantised = projector
        if projector.mixes_colours:
            self._affine = projector.drive_affine().astype(np.float32)
            if above_black:
                self._affine[:, 3] = 0.0
            self._quantised = replace(projector, max_radiance=1.0, cross_talk=None, black_level=(0.0, 0.0, 0.0))
        self._quantiser = _Quantiser.build(self._quantised)   # None: no table fine enough (e.g. 16-bit codes)

    def __call__(self, lf: LightField) -> np.ndarray:
        """Encode a light field for the projector.

        The drive is ``x = C^-1 (L / max_radiance - black_level)`` (just ``L / max_radiance`` without cross-talk
        and black level; ``C^-1 L / max_radiance`` when :attr:`above_black`), clipped to [0, 1]: radiance outside
        what the projector can emit is clipped.

        Args:
            lf: LightField ``(K, V, U, 3)`` radiance to emit.

        Returns:
            ``(H, W, 3)`` uint8 (bits <= 8) or uint16 codes.
        """
        img = self.codec.lightfield_to_unnormalised(lf)
        norm = self.codec.inv_norm3
        codes = np.empty(img.shape, self.projector.dtype)

        def encode_rows(rows: slice) -> None:
            block = img[rows]
            block *= norm[rows]                              # = lightfield_to_image(lf), bit for bit
            self._codes(block, out=codes[rows])

        _in_row_blocks(encode_rows, img.shape[0], img[0].size)
        return codes

    def quantise(self, radiance_image: np.ndarray) -> np.ndarray:
        """Per-pixel radiance -> projector codes (the encoder without the light field resampling).

        Args:
            radiance_image: ``(H, W, 3)`` radiance each projector pixel should make its lenslet emit.

        Returns:
            ``(H, W, 3)`` uint8 (bits <= 8) or uint16 codes.
        """
        img = np.ascontiguousarray(radiance_image, dtype=np.float32)
        if img.ndim != 3 or img.shape[-1] != 3:
            raise ValueError(f"radiance image must have shape (H, W, 3), got {img.shape}")
        return self._codes(img)

    def _codes(self, radiance: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """Codes of a C-contiguous ``(H, W, 3) float32`` radiance image (into ``out`` if given): the affine map to
        linear drive where the projector mixes colours, then the exact table (or the float quantiser without one)."""
        if self._affine is not None:
            radiance = cv2.transform(radiance, self._affine)     # radiance -> linear drive (max_radiance 1)
        if self._quantiser is not None:
            return self._quantiser(radiance, out=out)
        codes = _encode_float(self._quantised, radiance).astype(self.projector.dtype)
        if out is None:
            return codes
        out[...] = codes
        return out

    def emitted(self, image: np.ndarray) -> np.ndarray:
        """Radiance each projector pixel makes its lenslet emit (inverse of :meth:`__call__` up to quantisation).

        ``L = max_radiance * (black_level + C @ response.decode(code / levels))`` per pixel.

        Args:
            image: ``(H, W, 3)`` integer projector codes.

        Returns:
            ``(H, W, 3) float32`` radiance, W m^-2 sr^-1.
        """
        image = _check_codes(image, self.projector.device, "projector image")
        code = image.astype(np.float32) / np.float32(self.projector.levels)
        return self.projector.emit(self.projector.response.decode(code))


class ProjectorDrive:
    """The light field a projector's lenslets emit above its black as a linear map of its linear drive, and that
    map's exact transpose: X = S (d M^T), with d the drive (per pixel and channel, 0 to 1: the response curve's
    decoded code), M the emission per unit drive (the maximum radiance times the colour cross-talk) and S the
    codec's resampling of projector pixels onto the light field
    (:meth:`~lftransfer.lightfield.codec.LensletCodec.image_to_lightfield_matrix`: the same taps and weights). The
    fidelity floor fits a drive through the simulated rig's true projector with it, the projection solve through
    the rig model's (:mod:`lftransfer.transfer.surface_solve`).

    Args:
        encoder: a :class:`LightFieldEncoder` (its codec and projector).

    Attributes:
        emission: M, (3, 3) float32, W m^-2 sr^-1 per unit drive.
        resample: S, (K * V * U, H * W) float32 sparse.
        shape: (H, W, 3) of a drive image; lf_shape: (K, V, U, 3) of the light field.
    """

    def __init__(self, encoder: LightFieldEncoder) -> None:
        codec, projector = encoder.codec, encoder.projector
        self.emission = (projector.max_radiance * projector.cross_talk_matrix).astype(np.float32)
        self.resample = codec.image_to_lightfield_matrix()
        self._transpose = self.resample.T.tocsr()
        self.shape = (codec.device.height, codec.device.width, 3)
        self.lf_shape = (codec.array.K, codec.V, codec.U, 3)

    def __call__(self, drive: np.ndarray) -> np.ndarray:
        """X: (K, V, U, 3) float32 light field emitted above the black for an (H, W, 3) drive."""
        flat = np.ascontiguousarray(drive, np.float32).reshape(-1, 3) @ self.emission.T
        return np.asarray(self.resample @ flat, np.float32).reshape(self.lf_shape)

    def adjoint(self, x: np.ndarray) -> np.ndarray:
        """The transpose: a (K, V, U, 3) (or (K * V * U, 3)) light field -> (H, W, 3) float32."""
        flat = np.asarray(self._transpose @ np.ascontiguousarray(x, np.float32).reshape(-1, 3), np.float32)
        return (flat @ self.emission).reshape(self.shape)

"""The device boundary: integer camera/projector images <-> linear-radiance light fields.

- :class:`LightFieldDecoder`: raw LF camera image (uint16 codes) -> :class:`LightField` of radiance.
- :class:`LightFieldEncoder`: :class:`LightField` of radiance -> projector image (uint8/uint16 codes).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from lftransfer.lightfield.codec import LensletCodec
from lftransfer.lightfield.lightfield import LightField
from lftransfer.lightfield.response import ResponseCurve
from lftransfer.optics.device import LensletDevice
from lftransfer.optics.lens_array import LensArray

__all__ = ["CameraModel", "ProjectorModel", "LightFieldDecoder", "LightFieldEncoder"]


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
    """The projector behind the array: geometry, bit depth, response and brightness.

    Attributes:
        device: Pixel <-> ray geometry.
        bits: Bits per code value (8 -> uint8 images, more -> uint16).
        response: Linear drive <-> normalised code value.
        max_radiance: Radiance a full-code pixel makes its lenslet emit, W m^-2 sr^-1.
    """

    device: LensletDevice
    bits: int = 8
    response: ResponseCurve = field(default_factory=ResponseCurve)
    max_radiance: float = 1.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "bits", _check_bits(self.bits, "ProjectorModel"))
        if not (np.isfinite(self.max_radiance) and self.max_radiance > 0):
            raise ValueError(f"max_radiance must be positive, got {self.max_radiance!r}")
        object.__setattr__(self, "max_radiance", float(self.max_radiance))

    @property
    def levels(self) -> int:
        """Largest code value, ``2^bits - 1``."""
        return 2**self.bits - 1

    @property
    def dtype(self) -> type:
        """Integer dtype of projector images: uint8 up to 8 bits, else uint16."""
        return np.uint8 if self.bits <= 8 else np.uint16


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

    def radiance_image(self, raw: np.ndarray) -> np.ndarray:
        """Raw codes -> per-pixel radiance, ``decode(raw / (2^bits - 1)) / (exposure * vignetting)``.

        Args:
            raw: ``(H, W, 3)`` integer camera codes.

        Returns:
            ``(H, W, 3) float32`` radiance, W m^-2 sr^-1 (0 where vignetting is 0).
        """
        raw = _check_codes(raw, self.camera.device, "raw camera image")
        code = raw.astype(np.float32) / np.float32(self.camera.levels)
        linear = self.camera.response.decode(code)
        return (linear * self._inv_gain[..., None]).astype(np.float32, copy=False)

    def __call__(self, raw: np.ndarray) -> LightField:
        """Decode a raw camera image.

        Args:
            raw: ``(H, W, 3) uint16`` camera codes.

        Returns:
            LightField ``(K, V, U, 3) float32`` radiance.
        """
        return self.codec.image_to_lightfield(self.radiance_image(raw))

    def expose(self, radiance_image: np.ndarray) -> np.ndarray:
        """The noiseless forward model of the camera (see :meth:`CameraModel.expose`)."""
        return self.camera.expose(radiance_image)


class LightFieldEncoder:
    """LightField of radiance -> projector image (codec, brightness, inverse response, quantisation)."""

    def __init__(self, array: LensArray, projector: ProjectorModel, U: int, V: int) -> None:
        """Precompute the codec.

        Args:
            array: The lens array.
            projector: The projector model.
            U: Samples along u.
            V: Samples along v.
        """
        self.array, self.projector = array, projector
        self.codec = LensletCodec(array, projector.device, U, V)

    def __call__(self, lf: LightField) -> np.ndarray:
        """Encode a light field for the projector.

        Radiance above ``max_radiance`` or below 0 is clipped.

        Args:
            lf: LightField ``(K, V, U, 3)`` radiance to emit.

        Returns:
            ``(H, W, 3)`` uint8 (bits <= 8) or uint16 codes.
        """
        img = self.codec.lightfield_to_image(lf)
        linear = np.clip(img / np.float32(self.projector.max_radiance), 0.0, 1.0)
        code = self.projector.response.encode(linear)
        return np.round(code * np.float32(self.projector.levels)).astype(self.projector.dtype)

    def emitted(self, image: np.ndarray) -> np.ndarray:
        """Radiance each projector pixel makes its lenslet emit (inverse of :meth:`__call__` up to quantisation).

        Args:
            image: ``(H, W, 3)`` integer projector codes.

        Returns:
            ``(H, W, 3) float32`` radiance, W m^-2 sr^-1.
        """
        image = _check_codes(image, self.projector.device, "projector image")
        code = image.astype(np.float32) / np.float32(self.projector.levels)
        linear = self.projector.response.decode(code)
        return (linear * np.float32(self.projector.max_radiance)).astype(np.float32, copy=False)

"""Radiometric response of a device: linear signal <-> normalised code value (a per-channel power law)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["ResponseCurve"]


def _rgb(x: np.ndarray, name: str) -> np.ndarray:
    x = np.asarray(x)
    if x.ndim < 1 or x.shape[-1] != 3:
        raise ValueError(f"{name} must have shape (..., 3), got {x.shape}")
    return x


@dataclass(frozen=True)
class ResponseCurve:
    """A per-channel gamma curve: ``code = linear ** (1 / gamma)``, ``linear = code ** gamma``.

    Attributes:
        gamma: Exponent per RGB channel (> 0); 1 is a linear device.
    """

    gamma: tuple[float, float, float] = (1.0, 1.0, 1.0)

    def __post_init__(self) -> None:
        try:
            gamma = tuple(float(g) for g in self.gamma)
        except TypeError as exc:
            raise ValueError(f"gamma must be three positive numbers, got {self.gamma!r}") from exc
        if len(gamma) != 3 or not all(math.isfinite(g) and g > 0 for g in gamma):
            raise ValueError(f"gamma must be three positive finite numbers, got {self.gamma!r}")
        object.__setattr__(self, "gamma", gamma)

    @staticmethod
    def _apply(x: np.ndarray, exponent: np.ndarray) -> np.ndarray:
        dtype = x.dtype if np.issubdtype(x.dtype, np.floating) else np.float64
        y = np.power(np.clip(x.astype(np.float64, copy=False), 0.0, 1.0), exponent)
        return y.astype(dtype, copy=False)

    def encode(self, linear: np.ndarray) -> np.ndarray:
        """Linear signal -> normalised code value, ``clip(x, 0, 1) ** (1 / gamma)``.

        Args:
            linear: ``(..., 3)`` linear signal, nominally in [0, 1].

        Returns:
            ``(..., 3)`` code values in [0, 1] (float32 for float32 input, else float64).
        """
        x = _rgb(linear, "linear")
        return self._apply(x, 1.0 / np.asarray(self.gamma))

    @property
    def uniform(self) -> bool:
        """Whether all three channels share one gamma (then per-channel tables collapse to one)."""
        return self.gamma[0] == self.gamma[1] == self.gamma[2]

    def decode_table(self, levels: int, size: int = 65536) -> np.ndarray:
        """Decoded value of every integer code, as a lookup table for raw images.

        Entry ``[c, n]`` is ``decode(float32(n) / float32(levels))`` in float32 for channel c, i.e. bit for bit
        what :meth:`decode` gives for the float32 code ``n / levels`` (codes above ``levels`` clip to 1).

        Args:
            levels: Largest code value, ``2^bits - 1``.
            size: Number of entries (65536 covers every uint16 code).

        Returns:
            ``(3, size) float32`` table.
        """
        n = np.minimum(np.arange(size), levels).astype(np.float32) / np.float32(levels)
        lin = self.decode(np.ascontiguousarray(np.broadcast_to(n[:, None], (size, 3))))
        return np.ascontiguousarray(lin.T, dtype=np.float32)

    def decode(self, code: np.ndarray) -> np.ndarray:
        """Normalised code value -> linear signal, ``clip(code, 0, 1) ** gamma``.

        Args:
            code: ``(..., 3)`` code values in [0, 1].

        Returns:
            ``(..., 3)`` linear signal in [0, 1] (float32 for float32 input, else float64).
        """
        x = _rgb(code, "code")
        return self._apply(x, np.asarray(self.gamma))

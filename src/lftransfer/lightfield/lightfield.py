"""The light field on the interface: radiance per lenslet on a regular (u, v) grid (docs/architecture.md, "The
interface" and "Radiometry of a lenslet")."""

from __future__ import annotations

import numbers
from dataclasses import dataclass

import numpy as np

from lftransfer.optics.device import as_rays
from lftransfer.optics.lens_array import LensArray

__all__ = ["LightField"]


@dataclass(eq=False)
class LightField:
    """Radiance of the rays (k, d) crossing the lens array, sampled on a regular angular grid.

    Entry ``data[k, j, i]`` is the radiance L_k(d) of direction ``d = normalize(u_i, v_j, 1)`` averaged over
    lenslet k's aperture, with ``u_i = -a + (i + 0.5) 2a / U`` and ``a = array.half_width`` (likewise v_j).
    Samples whose ideal focal offset ``o = -f (u, v)`` lies outside lenslet k's cell belong to neighbours:
    they are masked (see :meth:`mask`) and hold zero by convention.

    Attributes:
        data: ``(K, V, U, 3) float32`` radiance, W m^-2 sr^-1.
        array: The lens array the light field belongs to.
    """

    data: np.ndarray
    array: LensArray

    def __post_init__(self) -> None:
        if not isinstance(self.array, LensArray):
            raise ValueError(f"array must be a LensArray, got {type(self.array).__name__}")
        data = np.asarray(self.data)
        if data.ndim != 4 or data.shape[-1] != 3:
            raise ValueError(f"data must have shape (K, V, U, 3), got {data.shape}")
        if data.shape[0] != self.array.K:
            raise ValueError(f"data has {data.shape[0]} lenslets, the array has K = {self.array.K}")
        if data.shape[1] < 1 or data.shape[2] < 1:
            raise ValueError(f"data needs at least one angular sample, got shape {data.shape}")
        self.data = np.asarray(data, dtype=np.float32)

    # ----------------------------------------------------------------- shape
    @property
    def K(self) -> int:
        """Number of lenslets."""
        return self.data.shape[0]

    @property
    def V(self) -> int:
        """Number of angular samples along v (rows of each lenslet's grid)."""
        return self.data.shape[1]

    @property
    def U(self) -> int:
        """Number of angular samples along u (columns of each lenslet's grid)."""
        return self.data.shape[2]

    @staticmethod
    def _axis(n: int, a: float) -> np.ndarray:
        return -a + (np.arange(n) + 0.5) * (2.0 * a / n)

    @property
    def u(self) -> np.ndarray:
        """Sample centres ``(U,) float64`` of u = d_x / d_z, spanning [-a, a]."""
        return self._axis(self.U, self.array.half_width)

    @property
    def v(self) -> np.ndarray:
        """Sample centres ``(V,) float64`` of v = d_y / d_z, spanning [-a, a]; row j <-> v_j, v_0 = -a."""
        return self._axis(self.V, self.array.half_width)

    def _uv(self) -> tuple[np.ndarray, np.ndarray]:
        return np.meshgrid(self.u, self.v)  # each (V, U)

    def directions(self) -> np.ndarray:
        """Unit directions of the grid samples.

        Returns:
            ``(V, U, 3) float64`` unit vectors ``normalize(u_i, v_j, 1)``.
        """
        uu, vv = self._uv()
        d = np.stack([uu, vv, np.ones_like(uu)], axis=-1)
        return d / np.linalg.norm(d, axis=-1, keepdims=True)

    def mask(self) -> np.ndarray:
        """Which grid samples are data: the ideal focal offset ``o = -f (u, v)`` lies in the lattice cell.

        Returns:
            ``(V, U) bool``.
        """
        uu, vv = self._uv()
        f = self.array.focal_length
        return self.array.in_cell(np.stack([-f * uu, -f * vv], axis=-1))

    def solid_angle_weights(self) -> np.ndarray:
        """Projected solid angle ``cos(theta) d(omega) = du dv / (1 + u^2 + v^2)^2`` of each sample, times mask.

        Returns:
            ``(V, U) float64`` weights, sr.
        """
        a = self.array.half_width
        du, dv = 2.0 * a / self.U, 2.0 * a / self.V
        uu, vv = self._uv()
        return du * dv / (1.0 + uu**2 + vv**2) ** 2 * self.mask()

    def power(self) -> np.ndarray:
        """Radiant flux through the array: ``aperture_area * sum_k sum_ij L * weights``.

        Returns:
            ``(3,) float64`` flux per channel, W.
        """
        w = self.solid_angle_weights()
        return self.array.aperture_area * np.einsum("kjic,ji->c", self.data.astype(np.float64), w)

    def lookup(self, k: np.ndarray, d: np.ndarray) -> np.ndarray:
        """Radiance of arbitrary rays (k, d), bilinear in (u, v).

        The bilinear weights are renormalised over the unmasked grid samples, so a ray near a cell border is
        not darkened by the zero-valued masked samples. The result is zero where ``k < 0``, ``d_z <= 0``,
        ``|u| > a`` or ``|v| > a``, where the ray's own ideal focal offset lies outside the cell, or where none
        of the four neighbouring samples is data.

        Args:
            k: ``(N,)`` integer lenslet indices.
            d: ``(N, 3)`` directions (need not be unit).

        Returns:
            ``(N, 3) float32`` radiance.
        """
        k, d = as_rays(k, d)
        a, f = self.array.half_width, self.array.focal_length
        U, V = self.U, self.V
        out = np.zeros((len(k), 3), np.float32)
        with np.errstate(divide="ignore", invalid="ignore"):
            u = d[:, 0] / d[:, 2]
            v = d[:, 1] / d[:, 2]
        ok = (k >= 0) & (k < self.K) & (d[:, 2] > 0) & (np.abs(u) <= a) & (np.abs(v) <= a)
        idx = np.flatnonzero(ok)
        idx = idx[self.array.in_cell(np.stack([-f * u[idx], -f * v[idx]], axis=-1))]
        if len(idx) == 0:
            return out
        kk = k[idx].astype(np.int64)
        fi = np.clip((u[idx] + a) / (2.0 * a) * U - 0.5, 0.0, U - 1)
        fj = np.clip((v[idx] + a) / (2.0 * a) * V - 0.5, 0.0, V - 1)
        i0 = np.minimum(np.floor(fi).astype(np.int64), max(U - 2, 0))
        j0 = np.minimum(np.floor(fj).astype(np.int64), max(V - 2, 0))
        ti, tj = fi - i0, fj - j0
        i1, j1 = np.minimum(i0 + 1, U - 1), np.minimum(j0 + 1, V - 1)
        m = self.mask()
        acc = np.zeros((len(idx), 3))
        wsum = np.zeros(len(idx))
        for jj, wj in ((j0, 1.0 - tj), (j1, tj)):
            for ii, wi in ((i0, 1.0 - ti), (i1, ti)):
                w = wj * wi * m[jj, ii]
                acc += w[:, None] * self.data[kk, jj, ii]
                wsum += w
        good = wsum > 1e-12
        out[idx[good]] = (acc[good] / wsum[good, None]).astype(np.float32)
        return out

    # ------------------------------------------------------------ construction
    @classmethod
    def zeros(cls, array: LensArray, U: int, V: int) -> "LightField":
        """An all-zero light field.

        Args:
            array: The lens array.
            U: Samples along u.
            V: Samples along v.

        Returns:
            LightField with ``(K, V, U, 3) float32`` zeros.
        """
        if int(U) < 1 or int(V) < 1:
            raise ValueError(f"U and V must be positive, got U={U}, V={V}")
        return cls(np.zeros((array.K, int(V), int(U), 3), np.float32), array)

    def copy(self) -> "LightField":
        """A deep copy of the data (the array is immutable and shared)."""
        return LightField(self.data.copy(), self.array)

    # -------------------------------------------------------------- arithmetic
    def _check_compatible(self, other: "LightField") -> None:
        if other.array != self.array:
            raise ValueError("light fields belong to different lens arrays")
        if other.data.shape != self.data.shape:
            raise ValueError(f"light field shapes differ: {self.data.shape} vs {other.data.shape}")

    def __add__(self, other: "LightField") -> "LightField":
        if not isinstance(other, LightField):
            return NotImplemented
        self._check_compatible(other)
        return LightField(self.data + other.data, self.array)

    def __radd__(self, other: object) -> "LightField":
        # supports sum([...]) which starts from the integer 0
        if isinstance(other, numbers.Number) and other == 0:
            return self.copy()
        return NotImplemented

    def __sub__(self, other: "LightField") -> "LightField":
        if not isinstance(other, LightField):
            return NotImplemented
        self._check_compatible(other)
        return LightField(self.data - other.data, self.array)

    def __neg__(self) -> "LightField":
        return LightField(-self.data, self.array)

    def __mul__(self, scalar: float) -> "LightField":
        if not isinstance(scalar, numbers.Real):
            return NotImplemented
        return LightField((self.data * np.float32(scalar)).astype(np.float32), self.array)

    __rmul__ = __mul__

    def __truediv__(self, scalar: float) -> "LightField":
        if not isinstance(scalar, numbers.Real):
            return NotImplemented
        if scalar == 0:
            raise ZeroDivisionError("division of a light field by zero")
        return LightField((self.data / np.float32(scalar)).astype(np.float32), self.array)

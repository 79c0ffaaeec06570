"""Dr.Jit arrays from NumPy and back, for the lights and the renderers: aligned uploads (kernels compiled once),
rays, and colours read back without fusing the read into the kernel that computes them."""

from __future__ import annotations

import numpy as np

from lftransfer.backend import mitsuba


def jit_array(kind, values: np.ndarray):
    """A Dr.Jit array (``kind``, e.g. ``mi.Float``) holding ``values`` (any shape, flattened), from a 64-byte
    aligned NumPy buffer.

    Dr.Jit reads a NumPy buffer in place, and the kernels that load from it are specialised to its alignment,
    which varies from one NumPy allocation to the next: such kernels would be compiled again call after call
    (hundreds of milliseconds each on the LLVM back-end). An aligned buffer keeps them the same.
    """
    flat = np.asarray(values).ravel()
    dtype = np.float32 if kind.__name__.startswith("Float") else np.uint32
    buf = np.empty(len(flat) + 64 // np.dtype(dtype).itemsize, dtype=dtype)
    start = (-buf.ctypes.data % 64) // buf.itemsize
    aligned = buf[start:start + len(flat)]
    aligned[:] = flat
    return kind(aligned)


def jit_rays(origins: np.ndarray, directions: np.ndarray):
    """``mi.Ray3f`` of (N, 3) origins and directions (any float dtype, stored as float32 through
    :func:`jit_array`)."""
    mi = mitsuba()
    return mi.Ray3f(mi.Point3f(*(jit_array(mi.Float, origins[:, i]) for i in range(3))),
                    mi.Vector3f(*(jit_array(mi.Float, directions[:, i]) for i in range(3))))


def to_numpy(color) -> np.ndarray:
    """(N, 3) float32 of a mi.Color3f (N,), evaluated first on its own: converting it directly would fuse the
    conversion, whose layout names N, into the kernel that computes it, and every new N would compile that
    kernel again."""
    import drjit as dr

    dr.eval(color)
    return np.stack([np.array(color[c], dtype=np.float32) for c in range(3)], axis=1)

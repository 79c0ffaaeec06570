"""The lens arrays of several light field interfaces as the synthetic side's renderer sees them (docs/architecture.md,
"Several interfaces").

With one interface every synthetic object stands on one side of one array, and light between synthetic objects
never crosses it. With several, a path from one synthetic object to another may cross the real objects' space:
through one array out of the synthetic side and through another back into it. The rig carries that light itself,
a bounce later (one interface's projector sends it, another's LF camera captures it), so the renderer must not carry
it too: a path between synthetic objects is cut where it crosses an array. The virtual point lights' shadow rays
and the primary rays (the view camera's, the light field's) are not cut: the rig's cameras do not record a point
light's own light, and the view camera sees the synthetic objects through the arrays.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lftransfer.backend import mitsuba
from lftransfer.optics.geometry import rigid_points_back, rigid_vectors

__all__ = ["Windows"]


@dataclass(frozen=True)
class Windows:
    """The arrays' rectangles in the renderer's frame.

    Attributes:
        to_frame: (I, 4, 4) float64, each array's frame (its plane z = 0) -> the renderer's frame.
        extents: (I, 4) float64, each array's (xmin, xmax, ymin, ymax) in its own plane, metres.
    """

    to_frame: np.ndarray
    extents: np.ndarray

    @classmethod
    def of(cls, arrays, poses) -> "Windows":
        """The windows of ``arrays`` (``LensArray``) standing at ``poses`` ((4, 4) array -> renderer frame)."""
        return cls(np.stack([np.asarray(p, np.float64) for p in poses]),
                   np.array([a.extent() for a in arrays], np.float64))

    def crossed(self, origins: np.ndarray, directions: np.ndarray, distance: np.ndarray) -> np.ndarray:
        """(N,) bool: which rays cross an array before ``distance`` (metres; inf: never stops).

        Args:
            origins, directions: (N, 3) rays in the renderer's frame, unit directions.
            distance: (N,) where each ray stops.
        """
        out = np.zeros(len(origins), bool)
        for m, (x0, x1, y0, y1) in zip(self.to_frame, self.extents):
            o, d = rigid_points_back(m, origins), rigid_vectors(m, directions, back=True)   # into the array's frame
            with np.errstate(divide="ignore", invalid="ignore"):
                t = -o[:, 2] / d[:, 2]
            x, y = o[:, 0] + t * d[:, 0], o[:, 1] + t * d[:, 1]
            out |= (t > 1e-6) & (t < distance) & (x >= x0) & (x <= x1) & (y >= y0) & (y <= y1)
        return out

    def crossed_jit(self, ray, distance):
        """mi.Bool (N,): :meth:`crossed` for an mi.Ray3f and mi.Float distances, in Dr.Jit."""
        mi = mitsuba()
        import drjit as dr

        out = mi.Bool(False)
        for m, (x0, x1, y0, y1) in zip(self.to_frame, self.extents):
            rot, shift = m[:3, :3], m[:3, 3]
            rel = [ray.o.x - float(shift[0]), ray.o.y - float(shift[1]), ray.o.z - float(shift[2])]
            dd = [ray.d.x, ray.d.y, ray.d.z]
            o = [sum(float(rot[j, i]) * rel[j] for j in range(3)) for i in range(3)]
            d = [sum(float(rot[j, i]) * dd[j] for j in range(3)) for i in range(3)]
            ok = dr.abs(d[2]) > 1e-12
            t = -o[2] / dr.select(ok, d[2], 1.0)
            x, y = o[0] + t * d[0], o[1] + t * d[1]
            out |= ok & (t > 1e-6) & (t < distance) & (x >= x0) & (x <= x1) & (y >= y0) & (y <= y1)
        return out

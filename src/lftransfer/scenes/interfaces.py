"""Where objects may stand when a scene has several light field interfaces (``[[interface]]``).

Each interface's frame has its array in z = 0 and its real side at z > 0. The real objects' space is the
intersection of the interfaces' real sides; a synthetic object stands on the synthetic side (z < 0) of at least one
interface, the interfaces it is seen through. With one interface (a ``[rig]`` scene) the rule is the one every
scene had: real objects at z > 0, synthetic ones at z < 0.
"""

from __future__ import annotations

import numpy as np

__all__ = ["box_corners", "facing_interfaces", "interface_names", "interfaces_named", "placements", "region_problem",
           "walls"]


def placements(interfaces) -> list[np.ndarray]:
    """(4, 4) float64 interface -> world transforms of a scene's ``interfaces`` (its ``[[interface]]`` tables), in
    order; the identity alone for a ``[rig]`` scene (none)."""
    return [i.to_world() for i in interfaces] or [np.eye(4)]


def interface_names(interfaces) -> list[str]:
    """The names of a scene's ``interfaces``, in order; ``["rig"]`` for a ``[rig]`` scene."""
    return [i.name for i in interfaces] or ["rig"]


def interfaces_named(scene) -> str:
    """The start of a one-line error about a scene of several interfaces: its file, the field and the interfaces
    (``"scene.toml: interface: the scene has 2 light field interfaces (front, side)"``)."""
    names, count = ", ".join(interface_names(scene.interfaces)), len(scene.interfaces)
    return f"{scene.source or '<scene>'}: interface: the scene has {count} light field interfaces ({names})"


def walls(interfaces, i: int) -> np.ndarray:
    """(N - 1, 4) float64 the array planes of every interface of ``interfaces`` but the ``i``-th, in the ``i``-th's
    frame: ``(n, d)`` with ``n . x + d`` the height of a point x above the plane towards that interface's real side
    (metres); (0, 4) for a ``[rig]`` scene."""
    faces = placements(interfaces)
    to_i = np.linalg.inv(faces[i])
    out = []
    for j, m in enumerate(faces):
        if j != i:
            local = to_i @ m
            out.append([*local[:3, 2], -float(local[:3, 2] @ local[:3, 3])])
    return np.asarray(out, np.float64).reshape(-1, 4)


def box_corners(bounds: np.ndarray) -> np.ndarray:
    """(8, 3) corners of an axis-aligned box given as (2, 3) [min, max] (metres)."""
    lo, hi = np.asarray(bounds, np.float64)
    return np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])


def _heights(points: np.ndarray, interfaces) -> np.ndarray:
    """(N, I) each point's height above each interface's array plane, towards its real side, metres."""
    out = []
    for m in placements(interfaces):
        out.append((points - m[:3, 3]) @ m[:3, 2])
    return np.stack(out, axis=1)


def facing_interfaces(bounds: np.ndarray, interfaces) -> list[int]:
    """Which of a scene's ``interfaces`` (indices) hold the whole box ``bounds`` ((2, 3) world metres) on their
    synthetic side: those it is seen through."""
    h = _heights(box_corners(bounds), interfaces)
    return [int(i) for i in np.flatnonzero((h < 0).all(axis=0))]


def region_problem(side: str, obj, interfaces, *, when: str = "") -> str | None:
    """What is wrong with where ``obj`` stands, in one line naming it, or None.

    Args:
        side: ``"real"`` or ``"synthetic"``.
        obj: the object (``ObjectConfig``), posed.
        interfaces: the scene's ``[[interface]]`` tables (none: one interface in the world's z = 0).
        when: appended to the message (e.g. " at t = 1.2 s").
    """
    lo, hi = obj.bounds()
    if not interfaces:
        if side == "real" and lo[2] <= 0:
            return f"a real object must lie in z > 0; {obj.name!r} spans z in [{lo[2]:.4g}, {hi[2]:.4g}] m{when}"
        if side == "synthetic" and hi[2] >= 0:
            return f"a synthetic object must lie in z < 0; {obj.name!r} spans z in [{lo[2]:.4g}, {hi[2]:.4g}] m{when}"
        return None
    h = _heights(box_corners(np.stack([lo, hi])), interfaces)
    names = interface_names(interfaces)
    if side == "real":
        worst = int(np.argmin(h.min(axis=0)))
        if h[:, worst].min() <= 0:
            return (f"a real object must lie on the real side of every interface; {obj.name!r} reaches "
                    f"{-h[:, worst].min() * 100:.3g} cm behind interface {names[worst]!r}{when}")
        return None
    if not (h < 0).all(axis=0).any():
        return (f"a synthetic object must lie wholly on the synthetic side of at least one interface; {obj.name!r} "
                "does not (its box's height over each interface's plane: "
                + ", ".join(f"{n} {h[:, i].min() * 100:.3g} to {h[:, i].max() * 100:.3g} cm"
                            for i, n in enumerate(names)) + f"){when}")
    return None

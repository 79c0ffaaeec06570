"""Which renderer renders a scene's synthetic half-space, and what it leaves out there.

:func:`resolve_renderer` turns the ``renderer`` choice (:data:`lftransfer.choices.Renderer`: "auto", "fast",
"exact") into the renderer a scene gets, "fast" or "exact"; :func:`lftransfer.settings.resolve_settings` calls it
once per run, so the settings a run reports name the renderer it used. :func:`make_renderer` builds that renderer
and :func:`approximations` says, one sentence each, what it leaves out of the scene or approximates.
"""

from __future__ import annotations

import math
from typing import Literal, Sequence

import numpy as np

from lftransfer.render import fast
from lftransfer.render.base import RayRenderer
from lftransfer.render.renderer import HalfSpaceRenderer

__all__ = ["STEP_PIXELS", "approximations", "make_renderer", "resolve_renderer", "visible_steps"]

STEP_PIXELS = 3.0
"""A cache triangle wider than this many view pixels shows a sharp shadow across a curved surface as steps (the
irradiance is linear across each triangle)."""

Resolved = Literal["fast", "exact"]


def _reflecting(objects: Sequence) -> list:
    return [o for o in objects if o.material.type != "emitter"]


def resolve_renderer(scene, kind: str = "auto") -> Resolved:
    """"fast" or "exact": what ``kind`` ("auto", "fast", "exact") means for this scene (a scene, or its synthetic
    part: its ``synthetic`` objects and its ``probe``).

    "auto" is the fast path where it renders the scene as the exact path does, within the exact path's own
    Monte Carlo error: diffuse, glossy and metal materials (glossy and metal of roughness at least
    ``fast.MIN_ROUGHNESS`` = 0.02, where the fast path's error against the converged exact path was measured to
    be no larger than the exact path's at its default samples; below it neither path converges, and the exact
    path stays the reference) and emitters; otherwise the exact path. Synthetic objects that light each other
    take the fast path too, whose interreflection gather renders the diffuse light they exchange (measured against
    the converged exact path, tests/render/test_fast.py::test_16) and whose glossy lobes read it; the glossy light
    they reflect onto each other is left out, and reports say so (Figs. 6 and 1b, each a glossy photograph on a
    glossy or metal frame: the same cross error and PSNR over the objects as the exact path against ground truth,
    benchmarks/glossy/fast_vs_exact.py). A half-space where nothing reflects light (no objects, or emitters only)
    always takes the exact path: there is no irradiance to cache, and the exact path only shows the emitters. So
    does a scene lit by a light probe (the fast path has no environment light).

    The result resolves to itself (``resolve_renderer(scene, resolve_renderer(scene, kind))`` is the same).

    Raises:
        ValueError: ``kind`` is none of the three, or "fast" on a scene with a light probe.
    """
    if kind not in ("auto", "fast", "exact"):
        raise ValueError(f"renderer must be 'auto', 'fast' or 'exact', got {kind!r}")
    if not _reflecting(scene.synthetic):
        return "exact"
    if getattr(scene, "probe", None) is not None:
        if kind == "fast":
            raise ValueError("renderer 'fast': the fast path does not render a light probe's environment (its "
                             "background and its light); use 'exact' or 'auto'")
        return "exact"
    if kind == "auto":
        ok = fast.supports(scene.synthetic) and all(fast.verified(o.material) for o in scene.synthetic)
        return "fast" if ok else "exact"
    return kind


def make_renderer(objects: Sequence, renderer: Resolved, max_depth: int, windows=None) -> RayRenderer:
    """The renderer ``renderer`` ("fast" or "exact", as :func:`resolve_renderer` gives it) of ``objects`` with
    ``max_depth`` surface interactions per path; ``windows``: several interfaces' arrays, where paths between objects
    are cut (:mod:`lftransfer.render.windows`)."""
    if renderer == "fast":
        return fast.CachedRenderer(objects, max_depth=max_depth, windows=windows)
    if renderer == "exact":
        return HalfSpaceRenderer(objects, max_depth=max_depth, windows=windows)
    raise ValueError(f"renderer must be 'fast' or 'exact' (resolve 'auto' first: resolve_renderer), got {renderer!r}")


def approximations(scene, renderer: Resolved, *, max_depth: int) -> list[str]:
    """What ``renderer`` ("fast" or "exact") leaves out of this scene or approximates at ``max_depth``, one
    sentence each (reports say it: an effect is never dropped silently). The exact path approximates nothing."""
    if renderer != "fast":
        return []
    notes = [f"fast path: diffuse irradiance cached at the vertices of a {fast.DEFAULT_MAX_EDGE * 1000:.0f} mm "
             f"tessellation, linear across each triangle"]
    glossy = [o for o in scene.synthetic if o.material.type in ("glossy", "metal")]
    if glossy:
        notes.append("fast path: glossy and metal lobes evaluated per ray, the light field's share by "
                     f"{fast.DEFAULT_LOBE_SAMPLES} or more directions drawn from the lobe "
                     f"({fast.DEFAULT_VIEW_LOBE_SAMPLES} per view ray), its occlusion read from the cache except "
                     "on cache triangles a shadow edge crosses")
    at_points = [o.name for o in glossy if o.material.roughness >= fast.PINHOLE_ROUGHNESS]
    if at_points:
        notes.append(f"fast path: in the view, the lobes of roughness >= {fast.PINHOLE_ROUGHNESS} "
                     f"({', '.join(at_points)}) computed at the cache points towards the camera "
                     f"({fast.PINHOLE_SAMPLES} x the directions) and interpolated across each triangle")
    rough = [o.name for o in glossy if 0 < o.material.roughness < fast.MIN_ROUGHNESS]
    if rough:
        notes.append(f"fast path: roughness below {fast.MIN_ROUGHNESS} ({', '.join(rough)}) is not verified against "
                     f"the exact path (whose sampling does not converge there); point-light highlights on "
                     f"tessellated spheres shift; --renderer exact is the reference")
    smooth = [o.name for o in glossy if o.material.roughness == 0]
    if smooth:
        notes.append(f"fast path: smooth (roughness 0) surfaces ({', '.join(smooth)}) mirror the captured light "
                     f"field, which the exact path (next-event estimation only) leaves black")
    if fast.exchanges_light(scene.synthetic):
        gathers = max_depth - 1
        names = ", ".join(o.name for o in _reflecting(scene.synthetic))
        if gathers < 1:
            notes.append(f"fast path: max_depth 1, so the light the synthetic objects ({names}) exchange is not "
                         f"rendered, as on the exact path")
        else:
            notes.append(f"fast path: the light the synthetic objects ({names}) exchange: their diffuse light "
                         f"gathered at the cache points ({fast.GATHER_RAYS} directions, {gathers} bounce"
                         f"{'s' if gathers > 1 else ''}) and reflected in their glossy lobes; the glossy light "
                         f"they reflect onto each other is left out (--renderer exact renders it)")
    return notes


def visible_steps(scene, renderer: Resolved) -> list[str]:
    """Where the fast path's tessellation may show in this scene's view, one warning each: a curved synthetic
    object (sphere, cylinder, mesh) on which a cache triangle (``fast.DEFAULT_MAX_EDGE``) spans more than
    :data:`STEP_PIXELS` view pixels, so that a sharp shadow across it is drawn as steps. The exact path has none.

    Args:
        scene: the scene, or its synthetic part (its objects and ``view``).
        renderer: "fast" or "exact" (no warning).
    """
    if renderer != "fast":
        return []
    view = scene.view
    pixel = math.radians(view.fov_deg) / view.resolution[0]            # radians per pixel, about the axis
    notes = []
    for o in scene.synthetic:
        if o.shape not in ("sphere", "cylinder", "mesh") or o.material.type == "emitter":
            continue
        distance = float(np.linalg.norm(np.asarray(o.translate, float) - np.asarray(view.origin, float)))
        span = fast.DEFAULT_MAX_EDGE / max(distance, 1e-6) / pixel
        if span > STEP_PIXELS:
            notes.append(f"fast path: on the curved {o.name!r} a {fast.DEFAULT_MAX_EDGE * 1000:.0f} mm cache "
                         f"triangle spans about {span:.0f} pixels of the view, so a sharp shadow across it shows as "
                         f"steps (its irradiance is linear across each triangle); --renderer exact renders it "
                         f"smoothly")
    return notes

"""What the fast path does with a material: which materials it renders and which it was verified on, which have a
glossy lobe, how the diffuse lobe weighs light by its cosine (:func:`diffuse_lobe_table`), and the BSDF context that
enables one lobe (:func:`bsdf_context`)."""

from __future__ import annotations

from typing import Sequence

import numpy as np

from lftransfer.backend import mitsuba
from lftransfer.render.shapes import bsdf_dict

TABLE_NODES = 64            # nodes of the diffuse lobe's cosine table (Mitsuba's roughplastic tabulates 64)
MATERIALS = ("diffuse", "glossy", "metal", "emitter")

#: Glossy and metal lobes at least this rough were measured against the exact path (tests/render/
#: measure_glossy.py): the fast path's error is no larger than the exact path's own at its default samples.
#: Below it, even 256 aperture points per lenslet leave the exact path unconverged, so neither is verified.
MIN_ROUGHNESS = 0.02


def supports(objects: Sequence) -> bool:
    """Whether the fast path renders these objects' materials (diffuse, glossy, metal, emitter)."""
    return all(getattr(o.material, "type", "diffuse") in MATERIALS for o in objects)


def verified(material) -> bool:
    """Whether the fast path's rendering of ``material`` was measured to be as accurate as the exact path's:
    diffuse and emitter materials, glossy and metal ones of roughness at least :data:`MIN_ROUGHNESS`."""
    return not is_glossy(material) or material.roughness >= MIN_ROUGHNESS


def is_glossy(material) -> bool:
    """Whether the material has a glossy lobe (glossy or metal)."""
    return material.type in ("glossy", "metal")


def diffuse_lobe_table(material) -> np.ndarray:
    """How the material's diffuse lobe weighs light by its cosine, relative to normal incidence.

    w(c) = f_d(n, wo(c)) / f_d(n, n) with cos(wo) = c, from Mitsuba's own BSDF evaluated with its diffuse
    component only (albedo 1, no texture): 1 for ``diffuse``, the coating's t(c) / t(1) for ``glossy``, 0 for
    ``metal`` and ``emitter`` (no diffuse lobe).

    Args:
        material: a scene material.

    Returns:
        (TABLE_NODES,) float32 at c = i / (TABLE_NODES - 1), read by linear interpolation.
    """
    mi = mitsuba()
    import drjit as dr

    if material.type == "diffuse":
        return np.ones(TABLE_NODES, np.float32)
    if material.type != "glossy":
        return np.zeros(TABLE_NODES, np.float32)
    white = material.model_copy(update={"albedo": [1.0, 1.0, 1.0], "texture": None})
    bsdf = mi.load_dict(bsdf_dict(white))
    c = np.maximum(np.linspace(0.0, 1.0, TABLE_NODES), 1e-4)
    si = dr.zeros(mi.SurfaceInteraction3f, TABLE_NODES)
    si.wi = mi.Vector3f(0.0, 0.0, 1.0)
    si.n = mi.Normal3f(0.0, 0.0, 1.0)
    si.sh_frame = mi.Frame3f(si.n)
    wo = mi.Vector3f(mi.Float(np.sqrt(1.0 - c**2)), 0.0, mi.Float(c))
    value = np.array(bsdf.eval(bsdf_context("diffuse"), si, wo), np.float64)[0] / c
    return (value / value[-1]).astype(np.float32)


def bsdf_context(lobe: str):
    """A BSDF context that enables only the diffuse lobe or only the glossy (and smooth) lobe."""
    mi = mitsuba()
    ctx = mi.BSDFContext()
    ctx.type_mask = mi.BSDFFlags.DiffuseReflection if lobe == "diffuse" \
        else mi.BSDFFlags.GlossyReflection | mi.BSDFFlags.DeltaReflection
    return ctx

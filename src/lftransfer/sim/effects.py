"""The effects a scene shows, measured on view images (a scene's ``[effect]``, docs/scene-format.md).

A moving synthetic object ``by`` changes what the view camera sees of a real object ``on``: it shadows it
(Fig. 5: the planet's shadow on the head) or ``on`` reflects it (Fig. 6: the photograph in the bowl). Each is
measured by comparing an image of the scene with an image of the same scene without ``by``, over the pixels where
``on`` is the surface seen, once for light field transfer and once for the path-traced ground truth, so that the
two curves against the distance between the objects can be compared.

- reflection: the mean radiance that ``by`` adds to ``on``'s pixels (W m^-2 sr^-1, mean of R, G and B);
- shadow: the fraction ``s = 1 - with / without`` of the light that ``by`` takes from each pixel of ``on``,
  averaged over 3 x 3 metric pixels so that noise does not make a shadow; its contrast is the largest ``s`` over
  ``on``'s lit pixels, and its penumbra width the difference of the
  radii of the areas (on ``on``'s surface, m^2) where ``s`` exceeds 10 % and 90 % of the contrast: for a round
  shadow, how far the edge takes to go from 10 % to 90 % of its depth, in metres (none for a shadow that takes
  less than a quarter of the light); its area is the surface area (m^2) where it takes at least half the light.

The pixels and their surface areas come from the real geometry, so this is verification code (it lives in the
simulator's package); both sides of the comparison use the same pixels.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Literal

import numpy as np

from scipy.ndimage import uniform_filter

from lftransfer.backend import mitsuba
from lftransfer.render.camera import sensor_dict, view_rays
from lftransfer.render.shapes import scene_dict
from lftransfer.sim.metrics import downsample, metric_factor

__all__ = ["MIN_CONTRAST", "EffectMeasure", "ObjectPixels", "measure_effect", "object_distance", "object_pixels"]

VIEW_SPP = 4                 # rays per view pixel that find the object's pixels (a 2 x 2 grid)
FULL_COVERAGE = 0.999        # a metric pixel belongs to the object when this fraction of its rays see it
LIT_FRACTION = 0.05          # shadow: pixels darker than this fraction of the brightest one are not measured
SMOOTHING = 3                # shadow: the light taken is averaged over this many metric pixels square
PENUMBRA_LEVELS = (0.1, 0.9)  # shadow: the edge runs between these fractions of the contrast
HALF_SHADOW = 0.5            # shadow: its area is where it takes at least this fraction of the light
MIN_CONTRAST = 0.25          # shadow: a fainter shadow has no penumbra worth the name (and noise could make one)


@dataclass(frozen=True)
class ObjectPixels:
    """Where a named object is the surface the view camera sees, at the metrics' resolution.

    Attributes:
        mask: (h, w) bool, the metric pixels wholly on the object (every ray of the block sees it first).
        area_m2: (h, w) float64, the object's surface area each metric pixel covers, m^2 (0 off the object).
        factor: the box-downsampling factor from the view's resolution to the metrics'.
    """

    mask: np.ndarray
    area_m2: np.ndarray
    factor: int


@dataclass(frozen=True)
class EffectMeasure:
    """One side's measure of an effect at one frame (the fields of the other kind are None).

    Attributes:
        kind: ``"reflection"`` or ``"shadow"``.
        added_radiance: reflection: mean radiance added over the object's pixels, W m^-2 sr^-1.
        contrast: shadow: the light taken from the shadow's darkest part, fraction in [0, 1].
        penumbra_m: shadow: width of the shadow's edge on the surface, m (None for a shadow fainter than
            :data:`MIN_CONTRAST`).
        area_m2: shadow: the surface area where the shadow takes at least half of the light, m^2 (its size:
            contrast and penumbra describe its darkest point and its edge, not how much of ``on`` it covers).
        pixels: metric pixels measured.
    """

    kind: Literal["reflection", "shadow"]
    added_radiance: float | None = None
    contrast: float | None = None
    penumbra_m: float | None = None
    area_m2: float | None = None
    pixels: int = 0

    def to_json(self) -> dict:
        return asdict(self)


def object_pixels(scene, name: str, *, target_width: int = 256) -> ObjectPixels:
    """The view pixels where the object ``name`` of ``scene`` is the first surface seen.

    Args:
        scene: a ``SceneConfig`` posed at one time (``scene.at(t)``), real objects included.
        name: the object's name (real or synthetic).
        target_width: the metrics' width (:func:`lftransfer.sim.metrics.metric_factor`).

    Returns:
        :class:`ObjectPixels`.
    """
    mi = mitsuba()
    view = scene.view
    w, h = view.resolution
    objects = list(scene.real) + list(scene.synthetic)
    target = [o for o in objects if o.name == name]
    if len(target) != 1:
        raise ValueError(f"object_pixels: expected one object named {name!r}, found {len(target)}")
    sensor = mi.load_dict(sensor_dict(view.origin, view.target, view.up, view.fov_deg, w, h))
    origins, dirs = view_rays(sensor, w, h, VIEW_SPP)
    rays = mi.Ray3f(mi.Point3f(*origins.T), mi.Vector3f(*dirs.T))
    hits = []
    for objs in (objects, target):
        mscene = mi.load_dict(scene_dict(objs), optimize=False)   # alive until the lazy result is read
        si = mscene.ray_intersect(rays)
        hits.append((np.array(si.is_valid()), np.array(si.t), np.array(si.n).T))
        del si, mscene
    (all_valid, all_t, _), (valid, t, normal) = hits
    seen = valid & all_valid
    seen[seen] = np.abs(t[seen] - all_t[seen]) <= 1e-6 * np.maximum(t[seen], 1.0)
    forward = np.asarray(view.target, np.float64) - np.asarray(view.origin, np.float64)
    forward /= np.linalg.norm(forward)
    pitch = 2.0 * np.tan(np.radians(view.fov_deg) / 2) / w          # pixel size on the plane at unit distance
    cos_axis = dirs @ forward
    cos_surface = np.abs(np.sum(normal * dirs, axis=1))
    with np.errstate(divide="ignore", invalid="ignore"):
        area = np.where(seen, pitch ** 2 * cos_axis ** 3 * t ** 2 / np.maximum(cos_surface, 1e-3), 0.0)
    f = metric_factor(w, target_width)
    coverage = downsample(seen.reshape(h, w, VIEW_SPP).mean(axis=2)[..., None], f)[..., 0]
    area_px = area.reshape(h, w, VIEW_SPP).mean(axis=2)
    area_m2 = downsample(area_px[..., None], f)[..., 0] * f * f
    return ObjectPixels(mask=coverage >= FULL_COVERAGE, area_m2=np.where(coverage >= FULL_COVERAGE, area_m2, 0.0),
                        factor=f)


def measure_effect(kind: str, image: np.ndarray, without: np.ndarray, pixels: ObjectPixels) -> EffectMeasure:
    """Measure an effect from an image with and an image without the object that causes it.

    Args:
        kind: ``"reflection"`` or ``"shadow"`` (module docstring).
        image: (H, W, 3) float32 linear radiance of the scene.
        without: (H, W, 3) float32 the same view without the object ``by``.
        pixels: :func:`object_pixels` of the object ``on``.

    Returns:
        :class:`EffectMeasure`.
    """
    with_ = downsample(image, pixels.factor).mean(axis=2).astype(np.float64)
    wo = downsample(without, pixels.factor).mean(axis=2).astype(np.float64)
    mask = pixels.mask
    if kind == "reflection":
        added = float((with_ - wo)[mask].mean()) if mask.any() else None
        return EffectMeasure(kind="reflection", added_radiance=added, pixels=int(mask.sum()))
    if kind != "shadow":
        raise ValueError(f"measure_effect: kind must be 'reflection' or 'shadow', got {kind!r}")
    lit = mask & (wo > LIT_FRACTION * (wo[mask].max() if mask.any() else 0.0))
    if not lit.any():
        return EffectMeasure(kind="shadow", pixels=0)
    taken = np.zeros_like(wo)
    taken[lit] = np.clip(1.0 - with_[lit] / wo[lit], 0.0, 1.0)
    # a 3 x 3 mean over the lit pixels: a noisy pixel does not make the shadow's contrast or edge
    weight = uniform_filter(lit.astype(np.float64), SMOOTHING)
    with np.errstate(invalid="ignore", divide="ignore"):
        smooth = np.where(lit, uniform_filter(taken, SMOOTHING) / weight, 0.0)
    contrast = float(smooth[lit].max())
    penumbra = None
    if contrast >= MIN_CONTRAST:
        lo, hi = (float(pixels.area_m2[lit & (smooth >= level * contrast)].sum()) for level in PENUMBRA_LEVELS)
        penumbra = float(np.sqrt(lo / np.pi) - np.sqrt(hi / np.pi))
    area = float(pixels.area_m2[lit & (smooth >= HALF_SHADOW)].sum())
    return EffectMeasure(kind="shadow", contrast=contrast, penumbra_m=penumbra, area_m2=area, pixels=int(lit.sum()))


def object_distance(scene, a: str, b: str) -> float:
    """Distance between the origins (``translate``) of the objects named ``a`` and ``b`` of a posed scene, m."""
    objects = {o.name: o for o in list(scene.real) + list(scene.synthetic)}
    return float(np.linalg.norm(np.asarray(objects[a].translate) - np.asarray(objects[b].translate)))

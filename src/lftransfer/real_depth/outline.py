"""The real objects' outline in the view camera, measured through the rig, and the depth inside it
(docs/architecture.md, "Occlusion").

The LF camera's depth (:func:`~lftransfer.lightfield.depth.plane_sweep`) carried into the view camera
(:func:`~lftransfer.real_depth.lightfield.splat_depth`) bleeds past the real objects' outlines: a light field
sample averages the rays of an angular step (6 mm wide at 10 cm for 16 directions over a window of +-0.5), so a
sample only partly on an object still finds the object's depth, and the point placed on its centre ray lands
beside the object. A view camera at an angle to the array sees these points a few pixels outside the object,
where they hide the synthetic objects behind. And the view camera sees faces of the real objects that face away
from the array, which the LF camera never sees.

The outline is put together from three measurements, each of which the rig makes:

1. **Centre rays** (:func:`centre_hits`): a sample keeps its depth only where it is at least
   :data:`CENTRE_SHARE` as bright as the brightest sample around it in its lenslet's image, under the projector's
   white light (its footprint mostly on the surface, so its centre ray meets it). Carried into the view, these
   points no longer land beside the objects.
2. **The clean plate** (:func:`plate_matte`): the view camera photographs the rig with the real objects taken
   away (:class:`~lftransfer.rig.requests.CleanPlate`, once, projector black); where a photograph of the real
   scene differs from it by more than :data:`PLATE_THRESHOLD` of its bright end, a real object is in front of
   the array: the lit faces, to the pixel.
3. **The visual hull** (:func:`visual_hull`): a point in front of the array is empty where some lenslet's ray
   through it returns no light under the projector's white light (the ray meets nothing). Marching each view
   pixel's ray from the camera towards the array, the first point that no lenslet shows empty is where the ray
   meets the hull of the real objects: its distance is the depth of a face the LF camera may never see, and a
   pixel whose ray meets no hull sees no real object.

Faces in shadow (neither the scene's light nor the projector reaches what the view camera sees) differ from
nothing in the photographs; they are closed by the union of (1) and (2) closed over :data:`CLOSING_STEPS`
angular steps of the light field at the objects' depth (a gap narrower than that is one the light field cannot
show empty either), within the hull. Pixels outside the outline get no real depth, so the depth composite is the
over operator there (:func:`lftransfer.composite.front_weight`).
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import binary_closing, binary_dilation, distance_transform_edt, maximum_filter
from scipy.spatial import cKDTree

from lftransfer.lightfield import LightField
from lftransfer.optics.geometry import pixel_rays, view_camera
from lftransfer.real_depth.lightfield import ViewDepth, lightfield_points, splat_depth
from lftransfer.rig.requests import CleanPlate, RealScene

__all__ = ["CENTRE_SHARE", "CLOSING_STEPS", "HULL_LIT_FRACTION", "PLATE_THRESHOLD", "centre_hits",
           "closing_radius_px", "lightfield_view_depths", "on_real_side", "outline_view_depth", "photograph_clean_plate",
           "plate_matte", "visual_hull"]

#: A sample's centre ray meets the surface where the sample is at least this share as bright as the brightest
#: sample of its lenslet's 3 x 3 angular neighbourhood (on the occlusion scene: 0.3 leaves 13 % of the view depth
#: off the objects, 0.5 leaves 3 %, 0.7 keeps a tenth of the objects' pixels).
CENTRE_SHARE = 0.5
#: A view pixel differs from the clean plate where |photograph - plate| (summed over channels) exceeds this
#: fraction of the photograph's 99th percentile (the view camera's noise and the array's own glints stay below).
PLATE_THRESHOLD = 0.01
#: A light field sample shows its ray empty where it is darker than this fraction of the white response's 99th
#: percentile (the ray meets nothing the projector lights).
HULL_LIT_FRACTION = 0.05
#: Lenslets a hull point is looked up in (its nearest, in the array plane).
HULL_LENSLETS = 19
#: A hull point needs this many lenslets that see it, every one of them lit, to count as inside.
HULL_MIN_VIEWS = 3
#: The hull's step along each view ray, metres along the array's normal.
HULL_STEP_M = 0.001
#: The outline is closed over this many angular steps of the light field at the objects' median depth.
CLOSING_STEPS = 2.0


def centre_hits(response: LightField, depth: np.ndarray, share: float = CENTRE_SHARE) -> np.ndarray:
    """(K, V, U) bool: the samples with a depth whose centre ray meets the surface (module docstring, 1).

    Args:
        response: the light field under the projector's white light alone
            (``MeasuredDepth.response`` of :func:`lftransfer.transfer.projection.measure_depth`), (K, V, U, 3).
        depth: (K, V, U) its plane sweep's depth, metres (NaN: none).
        share: :data:`CENTRE_SHARE`.
    """
    lum = response.data.mean(-1)
    brightest = maximum_filter(lum, size=(1, 3, 3), mode="nearest")
    return np.isfinite(depth) & (lum >= share * brightest) & (brightest > 0)


def photograph_clean_plate(rig, time_s: float) -> np.ndarray:
    """(H, W, 3) the view camera's photograph of the clean plate (:class:`~lftransfer.rig.requests.CleanPlate`: the
    real objects taken away, everything else as it is; the projector as it was left, black for
    :func:`plate_matte`); the real scene is then set up again at ``time_s`` seconds."""
    rig.setup(CleanPlate())
    plate = rig.capture_view().radiance
    rig.setup(RealScene(time_s=time_s))
    return plate


def plate_matte(photograph: np.ndarray, plate: np.ndarray, threshold: float = PLATE_THRESHOLD) -> np.ndarray:
    """(H, W) bool: the view pixels where the real scene's photograph differs from the clean plate.

    Args:
        photograph: (H, W, 3) the view camera's image of the real scene, projector black.
        plate: (H, W, 3) its image of the clean plate (:class:`~lftransfer.rig.requests.CleanPlate`), projector
            black.
        threshold: :data:`PLATE_THRESHOLD`.
    """
    photograph, plate = np.asarray(photograph, np.float32), np.asarray(plate, np.float32)
    if photograph.shape != plate.shape:
        raise ValueError(f"plate_matte: the photograph is {photograph.shape}, the clean plate {plate.shape}")
    bright = float(np.percentile(photograph.mean(-1), 99))
    if not bright > 0:
        return np.zeros(photograph.shape[:2], bool)
    return np.abs(photograph - plate).sum(-1) > threshold * bright


def closing_radius_px(depth: np.ndarray, U: int, model, view, steps: float = CLOSING_STEPS) -> int:
    """The outline's closing radius, view pixels: ``steps`` angular steps of the light field (``2 a / U`` in
    direction) at the real objects' median depth, as the view camera sees them at their median distance; 1
    where the depth is empty."""
    z = depth[np.isfinite(depth)]
    if not len(z):
        return 1
    zm = float(np.median(z))
    width_m = steps * zm * 2.0 * model.array.half_width / U
    K = view_camera(view)[0]
    to_world = np.linalg.inv(model.world_to_array())
    centre = to_world[:3, :3] @ np.array([0.0, 0.0, zm]) + to_world[:3, 3]   # on the array's axis at that depth
    distance = float(np.linalg.norm(centre - np.asarray(view.origin, np.float64)))   # from the camera's centre
    return max(1, int(np.ceil(width_m * K[0, 0] / max(distance, 1e-6))))


def visual_hull(response: LightField, depth: np.ndarray, model, view, candidates: np.ndarray) -> np.ndarray:
    """Where each candidate view pixel's ray first meets the hull of what the light field shows lit (module
    docstring, 3).

    Args:
        response: the white response (:func:`centre_hits`).
        depth: (K, V, U) its depth, metres: its range (0.5th to 99.5th percentile, 1 cm beyond each) bounds the
            march.
        model: the rig model (the array and its pose).
        view: the view camera; its centre must be on the real side (z > 0 in the array's frame).
        candidates: (H, W) bool, the pixels to march.

    Returns:
        (H, W) float32 distance from the camera's centre along each pixel's ray to the hull, metres; NaN where the
        ray meets none (or is no candidate).
    """
    array = model.array
    _K, V, U = depth.shape
    a = array.half_width
    data = LightField.zeros(array, U, V).mask()
    lum = response.data.mean(-1)
    lit = lum > HULL_LIT_FRACTION * np.percentile(lum[:, data], 99) if data.any() else np.zeros_like(lum, bool)
    lit &= data[None]
    out = np.full(candidates.shape, np.nan, np.float32)
    z = depth[np.isfinite(depth)]
    ys, xs = np.nonzero(candidates)
    if not len(z) or not len(xs):
        return out
    centre, rays = pixel_rays(view, np.stack([xs, ys], -1))
    m = model.world_to_array()
    c = m[:3, :3] @ centre + m[:3, 3]
    d = rays @ m[:3, :3].T
    if not c[2] > 0:
        raise ValueError("visual_hull: the view camera is not on the real side of the array")
    z_near = min(float(np.percentile(z, 99.5)) + 0.01, float(c[2]) - 1e-3)
    z_far = max(float(np.percentile(z, 0.5)) - 0.01, HULL_STEP_M)
    tree = cKDTree(array.centres)
    hit = np.full(len(xs), np.nan)
    alive = d[:, 2] < 0                                       # rays that head towards the array
    for zs in np.arange(z_near, z_far, -HULL_STEP_M):         # from the camera's side towards the array
        idx = np.flatnonzero(alive)
        if not len(idx):
            break
        t = (zs - c[2]) / d[idx, 2]
        points = c + t[:, None] * d[idx]
        nb = tree.query(points[:, :2], min(HULL_LENSLETS, array.K))[1].reshape(len(idx), -1)
        uv = (points[:, None, :2] - array.centres[nb]) / zs
        i = np.floor((uv[..., 0] + a) / (2 * a) * U).astype(np.int64)
        j = np.floor((uv[..., 1] + a) / (2 * a) * V).astype(np.int64)
        inside = (i >= 0) & (i < U) & (j >= 0) & (j < V)
        i, j = np.clip(i, 0, U - 1), np.clip(j, 0, V - 1)
        seen = inside & data[j, i]
        views = seen.sum(1)
        full = (views >= HULL_MIN_VIEWS) & ((seen & lit[nb, j, i]).sum(1) == views) & (t > 0)
        hit[idx[full]] = t[full]
        alive[idx[full]] = False
    out[ys, xs] = hit
    return out


def _disk(r: int) -> np.ndarray:
    y, x = np.mgrid[-r:r + 1, -r:r + 1]
    return x * x + y * y <= r * r


def _closed(mask: np.ndarray, r: int) -> np.ndarray:
    """``mask`` closed by a disc of radius ``r`` (padded, so that objects at the image's border stay)."""
    padded = np.pad(mask, r)
    return binary_closing(padded, structure=_disk(r))[r:-r, r:-r]


def outline_view_depth(response: LightField, depth: np.ndarray, model, view, photograph: np.ndarray,
                       plate: np.ndarray | None) -> ViewDepth:
    """The real scene's depth in the view camera, inside the real objects' measured outline (module docstring).

    Args:
        response: the light field under the projector's white light alone.
        depth: (K, V, U) its plane sweep's depth, metres (NaN: none).
        model: the rig model.
        view: the view camera, on the real side of the array.
        photograph: (H, W, 3) the view camera's image of the real scene, projector black.
        plate: (H, W, 3) its image of the clean plate, projector black; None: not photographed (the outline is
            the centre rays' points and the hull alone).

    Returns:
        :class:`ViewDepth` (source ``"outline"``): inside the outline, the centre rays' splatted depth where it
        has one, else the hull's (sigma: half an angular step's width at that distance), else the nearest splatted
        depth (sigma growing by a pixel's width per pixel away); NaN outside.
    """
    U = depth.shape[2]
    u, v = response.u, response.v
    points, sigma = lightfield_points(np.where(centre_hits(response, depth), depth, np.nan), u, v, model)
    splat = splat_depth(points, sigma, view, world_to_array=model.world_to_array(), source="centre rays")
    lit = plate_matte(photograph, plate) if plate is not None else np.zeros(splat.depth.shape, bool)
    base = splat.known | lit
    r = closing_radius_px(depth, U, model, view)
    hull = visual_hull(response, depth, model, view, binary_dilation(base, _disk(r)))
    inside = _closed(base, r) & (np.isfinite(hull) | base)
    K_px = view_camera(view)[0][0, 0]
    out = np.where(splat.known, splat.depth, hull)
    step_sigma = hull * (2.0 * model.array.half_width / U) * 0.5
    sig = np.where(splat.known, splat.sigma, step_sigma)
    if splat.known.any():
        dist, (iy, ix) = distance_transform_edt(~splat.known, return_indices=True)
        near = splat.depth[iy, ix]
        fill = inside & ~np.isfinite(out)
        out = np.where(fill, near, out)
        sig = np.where(fill, splat.sigma[iy, ix] + dist * near / K_px, sig)
    known = inside & np.isfinite(out)
    return ViewDepth(np.where(known, out, np.nan).astype(np.float32), np.where(known, sig, np.nan).astype(np.float32),
                     "outline")


def on_real_side(model, view) -> bool:
    """Whether the view camera's centre is in front of the array (on the real side, by more than a millimetre),
    where the outline can be measured (:func:`visual_hull` marches from there towards the array)."""
    m = model.world_to_array()
    return float(m[2, :3] @ np.asarray(view.origin, np.float64) + m[2, 3]) > 1e-3


def lightfield_view_depths(depth: np.ndarray, response: LightField | None, model, view,
                           photograph: np.ndarray | None, plate: np.ndarray | None, *,
                           as_it_is: bool = True) -> tuple[ViewDepth, ...]:
    """The LF camera's depth in the view camera: as it is (:func:`~lftransfer.real_depth.view_depth_from_lightfield`,
    source ``"lightfield"``), then, where the white response and the photograph are at hand and the camera is
    on the real side, inside the real objects' outline (:func:`outline_view_depth`, source ``"outline"``), which
    is the one to use (the last). With ``as_it_is`` False the depth as it is is left out where the outline is
    made (a live loop, which shows only the one it uses).

    Args:
        depth: (K, V, U) metres along the array's normal.
        response: the white response it was swept from, or None.
        model, view: the rig model and the view camera.
        photograph: (H, W, 3) the view camera's image of the real scene, projector black, or None.
        plate: its clean plate, or None.
    """
    from lftransfer.real_depth.lightfield import view_depth_from_lightfield

    if response is not None and photograph is not None and on_real_side(model, view):
        outlined = outline_view_depth(response, depth, model, view, photograph, plate)
        if not as_it_is:
            return (outlined,)
        return view_depth_from_lightfield(depth, response.u, response.v, model, view), outlined
    grid = LightField.zeros(model.array, depth.shape[2], depth.shape[1])
    return (view_depth_from_lightfield(depth, grid.u, grid.v, model, view),)

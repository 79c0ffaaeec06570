"""The real scene's depth as the view camera sees it, from what the rig measures (docs/architecture.md,
"Occlusion").

The depth-aware composite (:func:`lftransfer.composite.composite_depth`) needs, per view pixel, how far the real
surface is along the pixel's ray, and how sure that is. The LF camera already measures the real scene's depth
(:func:`lftransfer.lightfield.depth.plane_sweep`: per light field sample, metres along the array's normal). Each
sample's centre ray meets the surface at ``X = (c_k + z (u, v), z)`` in the array's frame; carried into the world
by the rig model's pose and projected into the view camera, those points are splatted into a depth buffer: each a
disc of the points' own spacing, every pixel of it at the distance where its ray meets the plane fitted through the
point and its nearest points (the surface's patch there), the nearest winning. Each pixel's standard deviation is
the depth step of the sweep there combined with the spread of the depths around it (large across a depth edge:
the composite is soft where the depth cannot tell).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from lftransfer.lightfield import LightField
from lftransfer.lightfield.depth import SWEEP_DEPTHS
from lftransfer.optics.geometry import pixel_rays, view_camera

__all__ = ["ViewDepth", "lightfield_points", "splat_depth", "view_depth_from_lightfield", "whole_aperture"]

MIN_SIGMA_M = 0.001            # no depth is known better than this, metres
MAX_RADIUS_PX = 6              # a point's disc, at most, pixels
MIN_RADIUS_PX = 2              # ... and at least (the points whole_aperture keeps are sparse near silhouettes)
NORMAL_NEIGHBOURS = 9          # points that fit a disc's plane
GRAZING_COS = 0.05             # a patch seen more grazing than this keeps its point's own distance
APERTURE_SHARE = 1.0           # of a lenslet's aperture that a kept sample's neighbours must cover (whole_aperture): 0
                               # leaves a halo, more than 1 leaves holes (the occlusion scene's false and missed real
                               # pixels together are fewest at 1, of 0.5, 0.75, 1, 1.5 and 2, with the oracle model)


@dataclass(frozen=True)
class ViewDepth:
    """A depth map of the real scene in the view camera.

    Attributes:
        depth: (H, W) float32 metres from the camera's centre along each pixel's ray to the real surface; NaN where
            unknown.
        sigma: (H, W) float32 its standard deviation, metres (NaN where unknown).
        source: where it came from (``"lightfield"``, ``"structured_light"``, ...).
    """

    depth: np.ndarray
    sigma: np.ndarray
    source: str

    @property
    def known(self) -> np.ndarray:
        """(H, W) bool: pixels with a depth."""
        return np.isfinite(self.depth)


def _sweep_step(z: np.ndarray) -> np.ndarray:
    """The plane sweep's spacing of candidate depths at depth ``z`` (uniform in 1 / z), metres."""
    inv = 1.0 / np.asarray(SWEEP_DEPTHS, float)
    step = float(np.abs(np.diff(inv)).mean())
    return np.square(z) * step


def lightfield_points(depth: np.ndarray, u: np.ndarray, v: np.ndarray, model) -> tuple[np.ndarray, np.ndarray]:
    """Where each light field sample's centre ray meets the real surface, in the world.

    Args:
        depth: (K, V, U) metres along the array's normal (:func:`~lftransfer.lightfield.depth.plane_sweep`;
            NaN: unknown).
        u, v: (U,), (V,) the light field's direction grid (``LightField.u``, ``.v``: the direction's x and y over
            its z).
        model: the :class:`~lftransfer.rig.RigModel` (the array's lenslets and its pose in the world).

    Returns:
        ((N, 3) world points, metres; (N,) their depth's standard deviation, metres: half the sweep's step there),
        for the N samples with a depth whose whole aperture sees the surface (:func:`whole_aperture`).
    """
    depth = np.asarray(depth, float)
    K, V, U = depth.shape
    if model.array.K != K or len(u) != U or len(v) != V:
        raise ValueError(f"depth has shape {depth.shape}, expected ({model.array.K}, {len(v)}, {len(u)})")
    data = LightField.zeros(model.array, U, V).mask()
    k, j, i = np.nonzero(whole_aperture(depth, u, model.array.pitch, data))
    z = depth[k, j, i]
    c = model.array.centres[k]
    local = np.stack([c[:, 0] + z * np.asarray(u, float)[i], c[:, 1] + z * np.asarray(v, float)[j], z], -1)
    to_world = np.linalg.inv(model.world_to_array())
    world = local @ to_world[:3, :3].T + to_world[:3, 3]
    return world, np.maximum(0.5 * _sweep_step(z), MIN_SIGMA_M)


def whole_aperture(depth: np.ndarray, u: np.ndarray, pitch: float, data: np.ndarray | None = None) -> np.ndarray:
    """(K, V, U) bool: the samples with a depth whose whole lenslet aperture sees the surface.

    A sample averages the rays through its lenslet's whole aperture, a pitch wide. Beside a silhouette some of them
    miss the object, and the sample still finds the object's depth; but its centre ray, along which
    :func:`lightfield_points` places the point, may miss the object by up to half a pitch, and such points land
    beside the object in the view camera (a halo of false real depth around every real object). A sample is kept
    where no data sample of its lenslet within :data:`APERTURE_SHARE` of the aperture's half width at its depth
    (``pitch / 2 / z``, in directions) lacks a depth.

    Args:
        depth: (K, V, U) metres, NaN where none.
        u: (U,) the direction grid (its spacing; v is taken alike).
        pitch: the lenslets' pitch, metres.
        data: (V, U) bool, the samples that are data (``LightField.mask``); None: all. Samples outside it never
            count as missing.
    """
    from scipy.ndimage import binary_dilation

    known = np.isfinite(depth)
    missing = ~known if data is None else ~known & np.asarray(data, bool)[None]
    step = float(np.abs(np.diff(np.asarray(u, float))).mean()) if len(u) > 1 else 1.0
    with np.errstate(divide="ignore", invalid="ignore"):
        half = APERTURE_SHARE * 0.5 * pitch / np.where(known, depth, 1.0)       # the aperture's half width, in u
        reach = np.where(known, np.ceil(half / step - 0.5), 0).astype(int)
    reach = np.clip(reach, 0, max(depth.shape[1:]))
    keep = known & (reach == 0)
    for r in np.unique(reach[known & (reach > 0)]):
        size = 2 * int(r) + 1
        near_missing = binary_dilation(missing, structure=np.ones((1, size, size), bool))
        keep |= known & (reach == r) & ~near_missing
    return keep


def splat_depth(points: np.ndarray, sigma: np.ndarray, view, *, radius_px: int | None = None,
                world_to_array: np.ndarray | None = None, source: str = "points") -> ViewDepth:
    """A depth map of the view camera from scattered surface points (a z-buffer of discs).

    Args:
        points: (N, 3) world points on the real surface, metres.
        sigma: (N,) each point's depth standard deviation, metres.
        view: the view camera (``lftransfer.scenes.ViewConfig``).
        radius_px: each point's disc radius, pixels (None: the projected points' median spacing, so that the
            discs close the gaps between them; at least :data:`MIN_RADIUS_PX`, at most :data:`MAX_RADIUS_PX`).
        world_to_array: (4, 4) the array's frame (``RigModel.world_to_array``): a pixel whose ray, at the distance
            a disc gives it, would be behind the array plane (z below minus its point's sigma in the array's frame)
            gets no depth. The real objects are all in front of the array, so such a depth is a disc spilt over a
            silhouette onto a pixel that looks past the real side (at the synthetic one: without this, it would
            hide the synthetic objects there). None: no such check.
        source: :attr:`ViewDepth.source`.

    Returns:
        :class:`ViewDepth`: per pixel the nearest disc's distance; its standard deviation that point's combined
        with the spread of the distances in the pixel's 3 x 3 neighbourhood (a depth edge is uncertain).
    """
    w, h = view.resolution
    K, R, t = view_camera(view)
    centre = -R.T @ t
    P = np.asarray(points, float).reshape(-1, 3)
    s = np.asarray(sigma, float).reshape(-1)
    cam = P @ R.T + t
    front = cam[:, 2] > 1e-6
    P, s, cam = P[front], s[front], cam[front]
    px = cam[:, :2] / cam[:, 2:3] @ K[:2, :2].T + K[:2, 2]
    dist = np.linalg.norm(P - centre, axis=1)
    inside = (px[:, 0] > -0.5 - MAX_RADIUS_PX) & (px[:, 0] < w - 0.5 + MAX_RADIUS_PX) \
        & (px[:, 1] > -0.5 - MAX_RADIUS_PX) & (px[:, 1] < h - 0.5 + MAX_RADIUS_PX)
    P, px, dist, s = P[inside], px[inside], dist[inside], s[inside]
    depth = np.full(h * w, np.inf)
    point_sigma = np.full(h * w, np.nan)
    if len(px) == 0:
        nan = np.full((h, w), np.nan, np.float32)
        return ViewDepth(nan, nan.copy(), source)
    if radius_px is None:
        spacing = cKDTree(px).query(px, 2)[0][:, 1] if len(px) > 1 else np.array([1.0])
        radius_px = int(min(MAX_RADIUS_PX, max(MIN_RADIUS_PX, np.ceil(np.median(spacing)))))
    r = int(radius_px)
    offsets = [(dx, dy) for dy in range(-r, r + 1) for dx in range(-r, r + 1) if dx * dx + dy * dy <= r * r + r]
    ix, iy = np.rint(px[:, 0]).astype(np.int64), np.rint(px[:, 1]).astype(np.int64)
    # each disc is a patch of the surface: the plane through the point fitted to its nearest points
    normal = _normals(P)
    offset = np.einsum("ij,ij->i", P - centre, normal)       # (P - c) . n
    ys, xs = np.mgrid[0:h, 0:w]
    rays = pixel_rays(view, np.stack([xs.ravel(), ys.ravel()], -1))[1]
    hits = []
    for dx, dy in offsets:                                   # a few dozen offsets, every point at once
        x, y = ix + dx, iy + dy
        ok = (x >= 0) & (x < w) & (y >= 0) & (y < h)
        idx = y[ok] * w + x[ok]
        facing = np.einsum("ij,ij->i", rays[idx], normal[ok])
        with np.errstate(divide="ignore", invalid="ignore"):
            along = offset[ok] / facing
        d = np.where((np.abs(facing) > GRAZING_COS) & (along > 0), along, dist[ok])
        np.minimum.at(depth, idx, d)
        hits.append((idx, d, s[ok]))
    for idx, d, sd in hits:                                  # the winning point's own sigma
        win = d == depth[idx]
        point_sigma[idx[win]] = sd[win]
    depth = depth.reshape(h, w)
    known = np.isfinite(depth)
    depth = np.where(known, depth, np.nan)
    spread = _local_spread(depth)
    sig = np.sqrt(np.square(point_sigma.reshape(h, w)) + np.square(spread))
    if world_to_array is not None:                           # the array-frame z of each pixel's depth
        m = np.asarray(world_to_array, float)
        z = ((centre + rays * depth.reshape(-1, 1)) @ m[2, :3] + m[2, 3]).reshape(h, w)
        known &= ~(z < -point_sigma.reshape(h, w))
        depth = np.where(known, depth, np.nan)
    return ViewDepth(depth.astype(np.float32), np.where(known, sig, np.nan).astype(np.float32), source)


def _normals(P: np.ndarray, k: int = NORMAL_NEIGHBOURS) -> np.ndarray:
    """(N, 3) unit normals of the surface through points ``P`` ((N, 3)): the direction of least spread of each
    point's ``k`` nearest points (principal components); (0, 0, 1) where there are too few."""
    n = len(P)
    if n < 3:
        return np.tile([0.0, 0.0, 1.0], (n, 1))
    idx = cKDTree(P).query(P, min(k, n))[1]
    nb = P[idx] - P[idx].mean(axis=1, keepdims=True)
    cov = np.einsum("nki,nkj->nij", nb, nb)
    return np.linalg.eigh(cov)[1][:, :, 0]


def _local_spread(depth: np.ndarray) -> np.ndarray:
    """(H, W) half the range of the known depths in each pixel's 3 x 3 neighbourhood (0 where alone)."""
    h, w = depth.shape
    pad = np.pad(depth, 1, constant_values=np.nan)
    stack = np.stack([pad[dy:dy + h, dx:dx + w] for dy in range(3) for dx in range(3)])
    with warnings.catch_warnings():                          # an all-NaN neighbourhood is a pixel with no depth
        warnings.simplefilter("ignore", RuntimeWarning)
        lo, hi = np.nanmin(stack, axis=0), np.nanmax(stack, axis=0)
    return np.where(np.isfinite(depth), 0.5 * (hi - lo), np.nan)


def view_depth_from_lightfield(depth: np.ndarray, u: np.ndarray, v: np.ndarray, model, view) -> ViewDepth:
    """The LF camera's depth of the real scene (:func:`lightfield_points`) carried into the view camera
    (:func:`splat_depth`)."""
    points, sigma = lightfield_points(depth, u, v, model)
    return splat_depth(points, sigma, view, world_to_array=model.world_to_array(), source="lightfield")

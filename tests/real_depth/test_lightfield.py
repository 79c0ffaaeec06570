"""The real scene's depth in the view camera from the LF camera's depth (lftransfer.real_depth).

What each test shows:
- test_01: a plane, parallel to the array or tilted by 17 degrees, given as the LF camera's depth of every sample,
  lands in the view camera at the exact distance along each pixel's ray (each disc is the plane fitted through its
  point's neighbours), from a camera on the real side and from one in the array's plane looking along it.
- test_02: no pixel whose ray looks past the real side (into the synthetic half-space) gets a depth, though the
  discs of the points near the horizon spill onto them; without the check they would (the negative control).
"""

from __future__ import annotations

import numpy as np
import pytest

from lftransfer.lightfield import LightField
from lftransfer.optics.geometry import backproject, pixel_rays
from lftransfer.real_depth import lightfield_points, splat_depth, view_depth_from_lightfield
from lftransfer.rig.model import nominal_rig
from lftransfer.scenes import builtin_scene, load_scene
from lftransfer.scenes.models import ViewConfig


@pytest.fixture(scope="module")
def model():
    return nominal_rig(load_scene(builtin_scene("fig4")).rig)


def _view(origin, target=(0.0, 0.0, 0.12)):
    return ViewConfig(resolution=(128, 96), origin=origin, target=target, up=(0.0, 1.0, 0.0), fov_deg=45.0)


def _plane_depth(model, U, plane):
    """(K, V, U) depth of every sample's centre ray on the plane z = a + b x + c y (array frame)."""
    lf = LightField.zeros(model.array, U, U)
    a, b, c = plane
    cx, cy = model.array.centres[:, 0][:, None, None], model.array.centres[:, 1][:, None, None]
    uu, vv = np.meshgrid(lf.u, lf.v)
    z = (a + b * cx + c * cy) / (1.0 - b * uu[None] - c * vv[None])     # z = a + b (cx + z u) + c (cy + z v)
    return np.where(lf.mask()[None], z, np.nan), lf


def _truth(view, plane):
    w, h = view.resolution
    ys, xs = np.mgrid[0:h, 0:w]
    px = np.stack([xs.ravel(), ys.ravel()], -1).astype(float)
    a, b, c = plane
    normal = np.array([-b, -c, 1.0])
    return np.linalg.norm(backproject(view, px, (0, 0, a), normal) - pixel_rays(view, px)[0], axis=1).reshape(h, w)


@pytest.mark.parametrize("origin", [(0.25, 0.10, 0.40), (0.55, 0.22, 0.0)])
def test_01_a_plane_lands_at_its_distances(model, origin):
    view = _view(origin)
    for plane in ((0.15, 0.0, 0.0), (0.13, 0.3, 0.0)):
        depth, lf = _plane_depth(model, 8, plane)
        vd = view_depth_from_lightfield(depth, lf.u, lf.v, model, view)
        assert vd.source == "lightfield" and vd.known.mean() > 0.2
        np.testing.assert_allclose(vd.depth[vd.known], _truth(view, plane)[vd.known], rtol=0, atol=1e-4)
        assert np.all(vd.sigma[vd.known] >= 0.001)


def test_02_no_depth_where_the_ray_looks_past_the_real_side(model):
    view = _view((0.55, 0.22, 0.0), target=(0.0, 0.0, 0.0))     # in the array's plane: half the rays go behind it
    depth, lf = _plane_depth(model, 8, (0.004, 0.0, 0.0))        # a surface 4 mm from the array
    vd = view_depth_from_lightfield(depth, lf.u, lf.v, model, view)
    w, h = view.resolution
    ys, xs = np.mgrid[0:h, 0:w]
    behind = (pixel_rays(view, np.stack([xs.ravel(), ys.ravel()], -1))[1][:, 2] < 0).reshape(h, w)
    assert behind.any() and vd.known.any() and not np.any(vd.known & behind)
    points, sigma = lightfield_points(depth, lf.u, lf.v, model)
    unchecked = splat_depth(points, sigma, view)              # the negative control: no half-space check
    assert np.any(np.isfinite(unchecked.depth) & behind)

"""The real objects' outline in the view camera and the depth inside it (lftransfer.real_depth.outline).

A box stands in front of the array. Its light field under the projector's white light is made analytically: each
sample's brightness is the share of its angular footprint (4 x 4 rays) that meets the box, spread over its 3 x 3
neighbours (the LF camera's pixels and the decoder's resampling); as the plane sweep does, a sample lit at all gets
the depth of the box there: the samples around the box's outline are lit in part and carry its depth though their
centre rays miss it (what makes the LF camera's depth bleed).

What each test shows:
- test_01: the centre-ray test keeps a sample where it is at least half as bright as the brightest around it and
  drops the dimmer ones at an outline, exactly.
- test_02: the clean plate's matte is where the photograph differs from the plate, relative to its bright end; a
  photograph of another size is refused with both shapes.
- test_03: the visual hull holds the whole box (every pixel whose ray meets the box meets the hull, no nearer
  than the box), and pixels whose rays pass more than an angular step beside it meet none.
- test_04: the outlined depth's edge lands within two view pixels of the box's true outline and the depth there
  is the box's, while the LF camera's depth carried into the view as it is bleeds past the outline by more (the
  negative control); without a clean plate the outline keeps only what the light field places.
- test_05: the closing radius is the angular steps' width at the objects' depth, in view pixels.
"""

from __future__ import annotations

import numpy as np
import pytest

from lftransfer.lightfield import LightField
from lftransfer.optics.geometry import pixel_rays
from lftransfer.real_depth import view_depth_from_lightfield
from lftransfer.real_depth.outline import (centre_hits, closing_radius_px, outline_view_depth, plate_matte,
                                           visual_hull)
from lftransfer.rig.model import nominal_rig
from lftransfer.scenes import builtin_scene, load_scene
from lftransfer.scenes.models import ViewConfig

BOX = np.array([[-0.012, 0.012], [-0.03, 0.03], [0.08, 0.086]])    # x, y, z ranges in the array frame, metres


@pytest.fixture(scope="module")
def model():
    return nominal_rig(load_scene(builtin_scene("fig4")).rig)


@pytest.fixture(scope="module")
def view():
    return ViewConfig(resolution=(128, 96), origin=(0.25, 0.10, 0.40), target=(0.0, 0.0, 0.09), up=(0.0, 1.0, 0.0),
                      fov_deg=30.0)


def _box_hits(origins: np.ndarray, directions: np.ndarray) -> np.ndarray:
    """(N,) distance along each ray (array frame) to the box, inf where it misses (slab test)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        t0 = (BOX[:, 0] - origins) / directions
        t1 = (BOX[:, 1] - origins) / directions
    near = np.nanmax(np.minimum(t0, t1), axis=1)
    far = np.nanmin(np.maximum(t0, t1), axis=1)
    return np.where((near <= far) & (far > 0), np.maximum(near, 0.0), np.inf)


def _response(model, U: int = 16):
    """(white response LightField, (K, V, U) swept depth) of the box."""
    array = model.array
    lf = LightField.zeros(array, U, U)
    du = lf.u[1] - lf.u[0]
    sub = (np.arange(4) + 0.5) / 4 - 0.5
    K = array.K
    share = np.zeros((K, U, U))
    first = np.full((K, U, U), np.inf)
    o = np.concatenate([array.centres, np.zeros((K, 1))], 1)[:, None, None, :] * np.ones((1, U, U, 1))
    for sy in sub:
        for sx in sub:
            uu, vv = np.meshgrid(lf.u + sx * du, lf.v + sy * du)
            d = np.stack([uu, vv, np.ones_like(uu)], -1)[None] * np.ones((K, 1, 1, 1))
            t = _box_hits(o.reshape(-1, 3), d.reshape(-1, 3)).reshape(K, U, U)
            share += np.isfinite(t) / 16                    # d_z = 1: t is the depth along the normal
            first = np.minimum(first, t)
    data = lf.mask()[None]
    # the LF camera's pixels and the decoder's resampling spread each sample's light over its neighbours
    from scipy.ndimage import maximum_filter, uniform_filter

    lit = uniform_filter(share * data, size=(1, 3, 3), mode="constant") * data
    lf.data[:] = lit[..., None]
    near = np.where(np.isfinite(first), first, np.inf)
    swept = -maximum_filter(-near, size=(1, 3, 3), mode="constant", cval=-np.inf)   # the nearest depth lit nearby
    depth = np.where(data & (lit > 0.02) & np.isfinite(swept), swept, np.nan)
    return lf, depth


def _view_truth(model, view) -> np.ndarray:
    """(H, W) distance to the box along each view pixel's ray, metres (inf: misses)."""
    w, h = view.resolution
    ys, xs = np.mgrid[0:h, 0:w]
    c, rays = pixel_rays(view, np.stack([xs.ravel(), ys.ravel()], -1))
    m = model.world_to_array()
    o = np.broadcast_to(m[:3, :3] @ c + m[:3, 3], rays.shape)
    return _box_hits(o, rays @ m[:3, :3].T).reshape(h, w)


def test_01_the_centre_rays_of_an_outline(model):
    lf = LightField.zeros(model.array, 4, 4)
    lf.data[:] = 0.0
    lf.data[0, 1, :, :] = np.array([0.2, 0.49, 1.0, 0.5])[:, None]      # one row of lenslet 0: outline, inside
    depth = np.where(lf.data[..., 0] > 0, 0.1, np.nan)
    hits = centre_hits(lf, depth)
    assert hits[0, 1].tolist() == [False, False, True, True]
    assert hits.sum() == 2
    depth[0, 1, 3] = np.nan                                     # no depth: never kept
    assert centre_hits(lf, depth).sum() == 1


def test_02_the_clean_plate_matte():
    plate = np.full((20, 30, 3), 0.01, np.float32)
    photo = plate.copy()
    photo[5:10, 5:12] = 2.0
    photo[12, 20] += 0.005                                      # below 1 % of the bright end
    photo[14, 22] += 0.05                                       # above
    matte = plate_matte(photo, plate)
    expected = np.zeros((20, 30), bool)
    expected[5:10, 5:12] = True
    expected[14, 22] = True
    np.testing.assert_array_equal(matte, expected)
    with pytest.raises(ValueError, match=r"\(20, 30, 3\).*\(20, 31, 3\)"):
        plate_matte(photo, np.zeros((20, 31, 3), np.float32))


def test_03_the_hull_holds_the_box(model, view):
    lf, depth = _response(model)
    truth = _view_truth(model, view)
    everywhere = np.ones(truth.shape, bool)
    hull = visual_hull(lf, depth, model, view, everywhere)
    box = np.isfinite(truth)
    assert box.sum() > 300
    assert np.all(np.isfinite(hull[box]))                     # every ray that meets the box meets the hull
    assert np.all(hull[box] <= truth[box] + 0.003)              # ... no farther than the box (a step of the march)
    from scipy.ndimage import distance_transform_edt

    far = distance_transform_edt(~box) > 12                     # past an angular step beside the box
    assert not np.any(np.isfinite(hull[far]))


def test_04_the_outline_follows_the_box(model, view):
    lf, depth = _response(model)
    truth = _view_truth(model, view)
    box = np.isfinite(truth)
    photo = np.where(box, 1.0, 0.0)[..., None].repeat(3, -1).astype(np.float32)
    plate = np.zeros_like(photo)
    from scipy.ndimage import distance_transform_edt

    beyond = distance_transform_edt(~box)                       # pixels from the box's outline, outside
    outlined = outline_view_depth(lf, depth, model, view, photo, plate)
    assert outlined.source == "outline"
    assert beyond[outlined.known].max() <= 2.0
    assert outlined.known[box].mean() > 0.99
    # the light field sees the box's face towards the array (6 mm behind its top along the normal, 8 mm along these
    # rays); the hull, where the light field places nothing, starts 1 cm beyond the deepest measured point (13 mm
    # along these rays): the depth lies within those bounds of the box's top
    err = (outlined.depth - truth)[outlined.known & box]
    assert err.min() > -0.014 and err.max() < 0.011
    plain = view_depth_from_lightfield(depth, lf.u, lf.v, model, view)
    assert beyond[plain.known].max() > 3.0                      # the negative control bleeds
    assert (plain.known & (beyond > 2)).sum() > 20
    alone = outline_view_depth(lf, depth, model, view, photo, None)   # no clean plate: what the light field places
    assert beyond[alone.known].max() <= 2.0 and 0.2 < alone.known[box].mean() < outlined.known[box].mean()


def test_05_the_closing_radius(model, view):
    depth = np.full((model.array.K, 16, 16), 0.09)
    r = closing_radius_px(depth, 16, model, view, steps=2.0)
    w = view.resolution[0]
    f_px = w / 2 / np.tan(np.radians(view.fov_deg) / 2)
    m = np.linalg.inv(model.world_to_array())
    axis = m[:3, :3] @ np.array([0, 0, 0.09]) + m[:3, 3]
    expected = 2 * 0.09 * 2 * model.array.half_width / 16 * f_px / np.linalg.norm(axis - np.array(view.origin))
    assert r == int(np.ceil(expected))
    assert closing_radius_px(np.full_like(depth, np.nan), 16, model, view) == 1

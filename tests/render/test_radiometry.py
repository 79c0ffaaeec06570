"""Lenslet radiometry against analytic irradiance (docs/architecture.md, "Radiometry of a lenslet")."""

from __future__ import annotations

import numpy as np
import pytest

from lftransfer.lightfield import LightField
from lftransfer.optics import LensArray
from lftransfer.render.lights import LightFieldLight, PointLight
from lftransfer.render.renderer import HalfSpaceRenderer
from lftransfer.scenes.format import ObjectConfig

PITCH = 0.02
ALBEDO = 0.6


def _plane(z: float, facing: str) -> ObjectConfig:
    """A large diffuse square at height z, normal towards the array."""
    rot = [0.0, 0.0, 0.0] if facing == "+z" else [180.0, 0.0, 0.0]
    return ObjectConfig.model_validate({"name": "plane", "shape": "rectangle", "size": [0.6, 0.6],
                                        "translate": [0.0, 0.0, z], "rotate_deg": rot,
                                        "material": {"type": "diffuse", "albedo": [ALBEDO] * 3}})


def _disk_lightfield(radiance: float, U: int = 16) -> LightField:
    """One round lenslet (radius PITCH/2) of uniform radiance over u, v in [-1, 1]."""
    array = LensArray(lattice="rect", rows=1, cols=1, pitch=PITCH, focal_length=PITCH / 2, aperture="round")
    lf = LightField.zeros(array, U, U)
    lf.data[...] = radiance
    return lf


def _radiance_at(renderer, x, lights, towards):
    """Radiance leaving point x (on a surface) towards direction ``towards``, by one traced ray."""
    o = np.asarray(x, float) + 0.01 * np.asarray(towards, float)
    rad, hit, _ = renderer.render_rays(o[None], -np.asarray(towards, float)[None], lights)
    assert hit[0]
    return rad[0]


@pytest.mark.parametrize("model", ["area", "point", "prefiltered"])
@pytest.mark.parametrize("side", ["synthetic", "real"])
def test_01_uniform_disk_over_parallel_plane(variant, model, side):
    """E = pi L R^2 / (R^2 + h^2) for the area model, pi L R^2 / h^2 for the point model."""
    L, R, h = 3.0, PITCH / 2, 0.02
    z = -h if side == "synthetic" else h
    renderer = HalfSpaceRenderer([_plane(z, "+z" if side == "synthetic" else "-z")], max_depth=1)
    light = LightFieldLight(_disk_lightfield(L), side=side, model=model, aperture_samples=512, jitter=False)
    up = np.array([0.0, 0.0, 1.0 if side == "synthetic" else -1.0])
    measured = _radiance_at(renderer, [0.0, 0.0, z], [light], up)
    exact_area = np.pi * L * R**2 / (R**2 + h**2)
    exact_point = np.pi * L * R**2 / h**2
    # The prefiltered model blurs the angular texture by the aperture's angle but keeps the point light's
    # 1 / r^2 falloff: for a uniform radiance it equals the point model.
    expected = (exact_area if model == "area" else exact_point) * ALBEDO / np.pi
    np.testing.assert_allclose(measured, expected, rtol=0.01)
    assert abs(exact_point - exact_area) / exact_area > 0.2   # the case separates the two models


def test_02_point_light_inverse_square(variant):
    renderer = HalfSpaceRenderer([_plane(-0.3, "+z")], max_depth=1)
    light = PointLight(np.array([0.0, 0.0, 0.0]), np.array([2.0, 1.0, 0.5]))
    measured = _radiance_at(renderer, [0.1, 0.0, -0.3], [light], [0.0, 0.0, 1.0])
    r2 = 0.1**2 + 0.3**2
    cos = 0.3 / np.sqrt(r2)
    np.testing.assert_allclose(measured, np.array([2.0, 1.0, 0.5]) * cos / r2 * ALBEDO / np.pi, rtol=1e-4)


def test_03_point_model_matches_mitsuba_projector_emitter(variant):
    """Our projective point light equals Mitsuba's ``projector`` emitter with T = I cos^3 / (pi scale)."""
    import mitsuba as mi

    from lftransfer.render.shapes import scene_dict

    U, h = 32, 0.05
    lf = _disk_lightfield(1.0, U)
    u = lf.u
    uu, vv = np.meshgrid(u, lf.v)
    lf.data[0] = np.stack([1 + uu, 1 + vv, 2 + uu * vv], -1)        # direction-dependent radiance
    d = lf.directions()
    cos = d[..., 2]
    intensity = lf.data[0] * lf.array.aperture_area * cos[..., None]     # I(w) = L A cos
    texture = intensity * cos[..., None] ** 3 / np.pi                     # Mitsuba convention, scale = 1
    # Projector at the lenslet looking along -z (synthetic side), light travelling along -d: with
    # look_at(o, o - z, up = y), texture column c maps to u = a (1 - 2 (c + 0.5) / U) and row r to v as in the
    # light field (first row = most negative v): so only the columns are reversed.
    tex = np.ascontiguousarray(texture[:, ::-1, :])
    a = lf.array.half_width
    fov = np.degrees(2 * np.arctan(a))
    plane = _plane(-h, "+z")
    d_scene = scene_dict([plane], extra={
        "proj": {"type": "projector", "irradiance": {"type": "bitmap", "bitmap": mi.Bitmap(tex.astype(np.float32)),
                                                      "filter_type": "nearest", "raw": True},
                 "fov": float(fov), "scale": 1.0,
                 "to_world": mi.ScalarTransform4f().look_at(origin=[0, 0, 0], target=[0, 0, -1], up=[0, 1, 0])},
    })
    scene = mi.load_dict(d_scene, parallel=False)
    renderer = HalfSpaceRenderer([plane], max_depth=1)
    ours = LightFieldLight(lf, side="synthetic", model="point")
    # Compare at a few points of the plane, away from texel borders.
    for (i, j) in [(16, 16), (8, 20), (25, 5)]:
        x = np.array([-h * u[i], -h * lf.v[j], -h])       # the ray (k=0, d_ij) continued to z = -h
        expected_ours = _radiance_at(renderer, x, [ours], [0, 0, 1])
        o = [float(c) for c in x + [0, 0, 0.01]]
        ray = mi.Ray3f(mi.Point3f(*o), mi.Vector3f(0, 0, -1))
        si = scene.ray_intersect(ray)
        ds, weight = scene.emitters()[0].sample_direction(si, mi.Point2f(0.5, 0.5))
        f = si.bsdf().eval(mi.BSDFContext(), si, si.to_local(ds.d))
        theirs = np.array(f * weight).ravel()
        np.testing.assert_allclose(expected_ours, theirs, rtol=0.03)


@pytest.mark.parametrize("reconstruction", ["linear", "box"])
def test_04_linear_reconstruction_relights_a_gradient_exactly(variant, reconstruction):
    """A light field whose radiance varies linearly across a rect array (the same in every direction) is read
    back exactly by the linear reconstruction: a point at depth h under it receives L(x) times the form factor
    of the square that the lenslets' window lets it see (half-width a h), as the continuous field would give.
    The box reconstruction, one value per lenslet, misses it (the negative control)."""
    pitch, h = 0.02, 0.03
    array = LensArray(lattice="rect", rows=9, cols=9, pitch=pitch, focal_length=pitch)   # a = 0.5
    lf = LightField.zeros(array, 16, 16)
    a0, grad = 1.0, np.array([25.0, -15.0])                            # radiance and its gradient, per metre
    lf.data[...] = (a0 + array.centres @ grad)[:, None, None, None]
    x = np.array([0.3 * pitch, 0.2 * pitch])                           # off the lattice's symmetry points
    renderer = HalfSpaceRenderer([_plane(-h, "+z")], max_depth=1)
    light = LightFieldLight(lf, side="synthetic", model="area", aperture_samples=1024, jitter=False,
                            reconstruction=reconstruction)
    measured = _radiance_at(renderer, [x[0], x[1], -h], [light], [0.0, 0.0, 1.0])
    half, n = array.half_width * h, 2000                                # the window's square, midpoint rule
    s = -half + (np.arange(n) + 0.5) * 2 * half / n
    r2 = s[:, None] ** 2 + s[None, :] ** 2 + h**2
    form = float(np.sum(h**2 / r2**2) * (2 * half / n) ** 2)
    expected = (a0 + x @ grad) * form * ALBEDO / np.pi
    error = abs(measured[0] - expected) / expected
    if reconstruction == "linear":
        assert error < 0.002, error                                   # measured 0.06 %
    else:
        assert error > 0.006, error                                   # measured 0.94 %


@pytest.mark.parametrize("lattice, window", [("rect", "edge"), ("hex", "edge"), ("rect", "cut")])
def test_04b_the_window_edge_extends_a_light_field_constant_in_direction_exactly(variant, lattice, window):
    """Under a light field whose radiance L is the same on every lenslet and in every direction (a far diffuse
    surface), ``window="edge"`` reads what a lens array with no window limit would record, out to the reach: a
    point at depth h receives E = pi L sin^2(theta_R), tan(theta_R) = EDGE_REACH a, whatever the lenslets'
    shape (the hexagonal lenslet's table is filled out to the square from its window's edge). ``"cut"`` (the
    negative control) receives the form factor of the window's square only."""
    from lftransfer.render.lights import EDGE_REACH

    pitch, h, L = 0.02, 0.03, 2.0
    array = LensArray(lattice=lattice, rows=9, cols=9, pitch=pitch, focal_length=pitch)   # a = 0.5 across
    lf = LightField.zeros(array, 16, 16)
    lf.data[...] = L * lf.mask()[None, :, :, None]
    renderer = HalfSpaceRenderer([_plane(-h, "+z")], max_depth=1)
    light = LightFieldLight(lf, side="synthetic", model="area", aperture_samples=1024, jitter=False,
                            reconstruction="linear", window=window)
    x = np.array([0.3 * pitch, 0.2 * pitch])
    measured = _radiance_at(renderer, [x[0], x[1], -h], [light], [0.0, 0.0, 1.0])[0]
    tan_r = EDGE_REACH * array.half_width
    disc = np.pi * L * tan_r**2 / (1 + tan_r**2) * ALBEDO / np.pi
    half, n = array.half_width * h, 2000                                # the window's square, midpoint rule
    s = -half + (np.arange(n) + 0.5) * 2 * half / n
    r2 = s[:, None] ** 2 + s[None, :] ** 2 + h**2
    square = L * float(np.sum(h**2 / r2**2) * (2 * half / n) ** 2) * ALBEDO / np.pi
    expected, other = (disc, square) if window == "edge" else (square, disc)
    assert abs(measured - expected) / expected < 0.005, (measured, expected)
    assert abs(other - expected) / expected > 0.15                     # the two readings are far apart


@pytest.mark.parametrize("renderer", ["exact", "fast"])
def test_05_emitting_sphere_lights_a_plane(variant, renderer):
    """A sphere of radiance L and radius R lights the point of a plane at distance D under its centre with
    E = pi L (R / D)^2 (its cone's projected solid angle); a ray that meets it sees L."""
    from lftransfer.render.fast import CachedRenderer
    from lftransfer.render.lights import EmitterLight

    L, R, D = 5.0, 0.01, 0.08
    sun = ObjectConfig.model_validate({"name": "sun", "shape": "sphere", "radius": R, "translate": [0, 0, -0.05],
                                       "material": {"type": "emitter", "radiance": [L, 0.5 * L, 0.2 * L]}})
    plane = _plane(-0.05 - D, "+z")
    r = CachedRenderer([sun, plane]) if renderer == "fast" else HalfSpaceRenderer([sun, plane], max_depth=1)
    light = EmitterLight(samples=64)
    measured = _radiance_at(r, [0.0, 0.0, -0.05 - D], [light], [0.3, 0.0, 1.0] / np.linalg.norm([0.3, 0.0, 1.0]))
    expected = np.pi * np.array([L, 0.5 * L, 0.2 * L]) * (R / D) ** 2 * ALBEDO / np.pi
    np.testing.assert_allclose(measured, expected, rtol=0.002)          # measured 0.01 % (exact), 0.07 % (fast)
    seen, hit, _ = r.render_rays(np.array([[0.0, 0.0, 0.0]]), np.array([[0.0, 0.0, -1.0]]), [light])
    np.testing.assert_allclose(seen[0], [L, 0.5 * L, 0.2 * L], rtol=1e-6)
    dark, _, _ = r.render_rays(np.array([[0.0, 0.0, 0.0]]), np.array([[0.0, 0.0, -1.0]]), [])
    np.testing.assert_array_equal(dark[0], 0.0)                         # no light given, no emission seen


def test_06_a_sun_on_the_horizon_is_sampled_along_its_edge(variant):
    """A sun half below a point's horizon (Fig. 5's terminator on the planet): with a square number of emitter
    samples they are stratified, so the estimate of its light varies much less between shading points than with
    random samples (the control: one sample fewer, not a square), with the same mean."""
    from lftransfer.render.lights import EmitterLight

    L, R, n = 5.0, 0.01, 4096
    sun = ObjectConfig.model_validate({"name": "sun", "shape": "sphere", "radius": R, "translate": [0.03, 0, -0.1],
                                       "material": {"type": "emitter", "radiance": [L, L, L]}})
    r = HalfSpaceRenderer([sun, _plane(-0.1, "+z")], max_depth=1)      # the sun's centre on the plane's level
    origins = np.tile([[0.0, 0.0, -0.09]], (n, 1))                     # n shading points, each its own samples

    def estimates(samples):
        rad, hit, _ = r.render_rays(origins, np.tile([[0.0, 0.0, -1.0]], (n, 1)), [EmitterLight(samples=samples)])
        assert hit.all()
        return rad[:, 0]

    stratified, random = estimates(16), estimates(15)
    mean = random.mean()
    assert mean > 0 and abs(stratified.mean() - mean) < 0.02 * mean
    # measured: relative spread 0.18 stratified, 0.34 random
    assert stratified.std() < 0.22 * mean and random.std() > 1.6 * stratified.std()


def test_incident_radiance_along_a_direction(variant):
    """LightFieldLight.incident reads the lenslet whose aperture a ray meets, at the ray's direction: the disk's
    radiance through the aperture, nothing beside it or beyond the window, and the density M r^2 / (A cos) of
    the aperture points ``illuminate`` reads."""
    import mitsuba as mi

    L = 3.0
    lf = _disk_lightfield(L)
    light = LightFieldLight(lf, side="synthetic", model="area", aperture_samples=4)
    x = np.array([[0.0, 0.0, -0.02]] * 4)
    w = np.array([[0.1, 0.05, 1.0],          # through the aperture (meets the plane 2 mm from the centre)
                  [0.6, 0.0, 1.0],           # meets the plane 12 mm out: beside the round aperture
                  [0.0, 0.0, -1.0],          # away from the array
                  [0.0, 0.0, 1.0]])
    w /= np.linalg.norm(w, axis=1, keepdims=True)
    found = light.incident(mi.Point3f(*x.T.astype(np.float32)), mi.Vector3f(*w.T.astype(np.float32)), mi.Bool(True))
    radiance = np.array(found.radiance).T
    np.testing.assert_allclose(radiance[[0, 3]], L, rtol=1e-5)
    np.testing.assert_array_equal(radiance[[1, 2]], 0.0)
    np.testing.assert_array_equal(np.array(found.lenslet), [0, 1, 1, 0])      # K = 1: none
    r = 0.02 / w[[0, 3], 2]
    expected = 4 * r**2 / (lf.array.aperture_area * w[[0, 3], 2])
    np.testing.assert_allclose(np.array(found.density)[[0, 3]], expected, rtol=1e-5)
    with pytest.raises(ValueError, match="area"):
        LightFieldLight(lf, side="synthetic", model="point").incident(
            mi.Point3f(*x.T.astype(np.float32)), mi.Vector3f(*w.T.astype(np.float32)), mi.Bool(True))


def test_plane_lookup_follows_the_lens_array(variant):
    """The raster behind ``incident`` reads each cell as LensArray.lenslet_at / interpolation read its centre, so
    any point is read within pitch / 128 of where it is: box lenslets agree away from cell edges, linear weights
    within the weights' slope over that distance."""
    from lftransfer.render.lights import PLANE_CELLS_PER_PITCH, plane_lookup

    array = LensArray(lattice="hex", rows=3, cols=4, pitch=0.0254, focal_length=0.0254)
    xmin, xmax, ymin, ymax = array.extent()
    points = np.random.default_rng(0).uniform([xmin, ymin], [xmax, ymax], (2000, 2))
    for reconstruction in ("box", "linear"):
        look = plane_lookup(array, reconstruction)
        cell = ((points[:, 1] - look.y0) // look.cell).astype(int) * look.nx + \
            ((points[:, 0] - look.x0) // look.cell).astype(int)
        idx = np.array(look.lenslets).reshape(-1, 3)[cell]
        wts = np.array(look.weights).reshape(-1, 3)[cell]
        # points farther than a raster cell from every lattice cell edge (where the reading may jump)
        own = array.lenslet_at(points)
        far = own >= 0
        for step in ([look.cell, 0], [-look.cell, 0], [0, look.cell], [0, -look.cell]):
            far &= array.lenslet_at(points + step) == own
        assert far.sum() > 1500
        if reconstruction == "box":
            np.testing.assert_array_equal(idx[far, 0], own[far])
            np.testing.assert_array_equal(wts[far, 0], 1.0)
        else:
            ref_idx, ref_w = array.interpolation(points)
            rows = np.arange(len(points))[:, None]
            dense, ours = np.zeros((len(points), array.K)), np.zeros((len(points), array.K))
            np.add.at(dense, (rows, np.where(ref_w > 0, ref_idx, 0)), ref_w)
            np.add.at(ours, (rows, idx), wts)
            # a hat function falls from 1 to 0 over a lattice row, pitch sqrt(3) / 2, and the cell centre is at
            # most cell / sqrt(2) away
            slope = 1.0 / (array.pitch * np.sqrt(3) / 2)
            hull = far & ((ref_w > 0).sum(1) == 3) & ((wts > 0).sum(1) == 3)   # the outer half cells read
            assert hull.sum() > 500                                           # their own lenslet: a jump
            assert np.abs(ours - dense)[hull].max() <= 2 * slope * look.cell / np.sqrt(2)     # margin 2
    assert PLANE_CELLS_PER_PITCH == 64

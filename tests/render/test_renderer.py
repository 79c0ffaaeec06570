"""Renders of one half-space: view images (alpha, depth) and light fields."""

from __future__ import annotations

import numpy as np

from lftransfer.optics import LensArray
from lftransfer.render.camera import sensor_dict
from lftransfer.render.lights import PointLight
from lftransfer.render.base import aperture_offsets
from lftransfer.render.renderer import HalfSpaceRenderer
from lftransfer.scenes.format import ObjectConfig


def _sphere(z, radius, material=None):
    return ObjectConfig.model_validate({"name": "ball", "shape": "sphere", "radius": radius, "translate": [0, 0, z],
                                        "material": material or {"type": "diffuse", "albedo": [0.5] * 3}})


def test_01_view_alpha_and_depth(variant):
    from lftransfer.backend import mitsuba

    mi = mitsuba()
    r = HalfSpaceRenderer([_sphere(-0.5, 0.1)], max_depth=1)
    sensor = mi.load_dict(sensor_dict([0, 0, 0.5], [0, 0, -0.5], [0, 1, 0], 40.0, 64, 48))
    img = r.render_view(sensor, 64, 48, [PointLight(np.array([0.0, 0.0, 0.5]), np.ones(3))], spp=4)
    assert img.rgb.shape == (48, 64, 3) and img.alpha.shape == (48, 64)
    assert img.alpha[24, 32] == 1.0 and img.alpha[0, 0] == 0.0 and np.isinf(img.depth[0, 0])
    np.testing.assert_allclose(img.depth[23:25, 31:33], 0.9, atol=2e-3)      # camera 1 m away, radius 0.1
    # Coverage of the disk: pi r'^2 of the image, r' the sphere's angular radius on the film.
    tan_half = np.tan(np.radians(20.0))
    r_px = np.tan(np.arcsin(0.1 / 1.0)) / tan_half * 32
    assert abs(img.alpha.sum() - np.pi * r_px**2) < 0.03 * np.pi * r_px**2
    # Premultiplied colour: edge pixels are darker than interior ones in proportion to alpha.
    assert np.all(img.rgb[img.alpha == 0] == 0)


def test_02_lightfield_is_masked_and_symmetric(variant):
    """A sphere on the axis of the central lenslet, lit from that lenslet, sends it a light field symmetric
    under (u, v) -> (-u, -v) (each entry's rays land in its place); samples outside each lenslet's cell are zero,
    and have no rays cast."""
    r = HalfSpaceRenderer([_sphere(-0.1, 0.03)], max_depth=1)
    light = PointLight(np.array([0.0, 0.0, 0.0]), np.ones(3))
    for lattice in ("hex", "rect"):
        array = LensArray(lattice=lattice, rows=3, cols=3, pitch=0.0254, focal_length=0.0254)
        for model in ("point", "area"):
            cast = []
            inner = r.render_samples
            r.render_samples = lambda o, d, *a, **k: cast.append(len(o)) or inner(o, d, *a, **k)
            lf = r.render_lightfield(array, [light], 16, 16, model=model, spp=16)
            del r.render_samples
            assert np.all(lf.data[:, ~lf.mask()] == 0)
            assert cast == [array.K * int(lf.mask().sum()) * 16]     # rays for the entries with data only
            if lattice != "rect":
                continue
            centre = lf.data[4].sum(-1)                   # lenslet 4 sits at the origin
            assert centre.max() > 0
            if model == "point":
                np.testing.assert_allclose(centre, centre[::-1, ::-1], rtol=1e-3, atol=1e-4 * centre.max())
            else:   # aperture averages are Monte Carlo estimates: symmetric on average
                uu, vv = np.meshgrid(lf.u, lf.v)
                step = lf.u[1] - lf.u[0]
                assert abs((centre * uu).sum() / centre.sum()) < 0.1 * step
                assert abs((centre * vv).sum() / centre.sum()) < 0.1 * step


def test_03_aperture_offsets_cover_the_aperture():
    array = LensArray(lattice="hex", rows=2, cols=2, pitch=0.02, focal_length=0.02)
    off = aperture_offsets(array, 5000, 4, seed=3)
    assert off.shape == (5000, 4, 2)
    assert np.all(array.in_aperture(off.reshape(-1, 2).astype(np.float64) * (1 - 1e-6)))
    np.testing.assert_allclose(off.reshape(-1, 2).mean(0), 0.0, atol=3e-4)
    # Within one group the points are spread out (stratified), not clumped.
    spread = np.linalg.norm(off[:, 0] - off[:, 1], axis=-1)
    assert spread.min() > 0.05 * array.pitch

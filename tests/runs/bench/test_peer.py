"""The benchmark's peer (Mitsuba's path integrator, projector emitters, batch sensor) against our renderer."""

from __future__ import annotations

import numpy as np
import pytest

from lftransfer.runs.bench.peer import PeerRenderer, projector_texture, rmse, spp_for_rmse
from lftransfer.lightfield import LightField
from lftransfer.optics import LensArray
from lftransfer.render.lights import LightFieldLight
from lftransfer.render.renderer import HalfSpaceRenderer
from lftransfer.scenes.format import ObjectConfig

U = 12
SUPER = 4            # sub-samples per axis of the pixel-averaged reference


def _box() -> ObjectConfig:
    """A large diffuse slab whose front face (z = -0.08) fills every lenslet camera's view."""
    return ObjectConfig.model_validate({"name": "box", "shape": "box", "size": [0.3, 0.3, 0.04],
                                        "translate": [0.0, 0.0, -0.10],
                                        "material": {"type": "diffuse", "albedo": [0.8, 0.6, 0.4]}})


def _incident(lattice: str) -> LightField:
    """A smooth, direction- and lenslet-dependent incident light field, different per channel.

    A window that vanishes at |(u, v)| = a (inside every cell) keeps the light on the box smooth, so that the
    peer's pixel-averaged samples and our pixel-centre samples differ little.
    """
    array = LensArray(lattice=lattice, rows=2, cols=3, pitch=0.0254, focal_length=0.0254)
    lf = LightField.zeros(array, U, U)
    a = array.half_width
    uu, vv = np.meshgrid(lf.u, lf.v)
    window = np.clip(1.0 - (uu**2 + vv**2) / a**2, 0.0, None) ** 2 * lf.mask()
    for k in range(array.K):
        rgb = np.stack([1 + 0.9 * uu / a, 1 + 0.9 * vv / a, 1 + 0.5 * np.sin(3 * uu / a + k)], axis=-1)
        lf.data[k] = rgb * window[..., None] * (1.0 + 0.2 * k)
    return lf


def _ours(incident: LightField, supersample: int = 1) -> LightField:
    """Our point-model render; with ``supersample`` > 1 averaged over each sample's pixel footprint (s x s)."""
    light = LightFieldLight(incident, side="synthetic", model="point")
    renderer = HalfSpaceRenderer([_box()], max_depth=1)
    if supersample == 1:
        return renderer.render_lightfield(incident.array, [light], U, U, model="point", spp=1)
    s, a, K = supersample, incident.array.half_width, incident.K
    axis = -a + (np.arange(U * s) + 0.5) * (2 * a / (U * s))
    uu, vv = np.meshgrid(axis, axis)
    d = -np.stack([uu, vv, np.ones_like(uu)], axis=-1).reshape(-1, 3)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    origins = np.zeros((K, len(d), 3))
    origins[..., :2] = incident.array.centres[:, None, :]
    radiance, _, _ = renderer.render_rays(origins.reshape(-1, 3), np.tile(d, (K, 1)), [light])
    out = LightField.zeros(incident.array, U, U)
    out.data[...] = radiance.reshape(K, U, s, U, s, 3).mean(axis=(2, 4)) * out.mask()[None, :, :, None]
    return out


@pytest.fixture(scope="module", params=["hex", "rect"])
def setup(request, variant):
    incident = _incident(request.param)
    peer = PeerRenderer([_box()], incident, U, U, max_depth=1)
    point = _ours(incident)
    pixel = _ours(incident, SUPER)
    mean = float(point.data[:, point.mask()].mean())
    return incident, peer, point, pixel, mean


def test_01_matches_our_renderer_and_orientation(setup):
    incident, peer, point, pixel, mean = setup
    lf = peer.render(4096, seed=0)
    assert lf.data.shape == (incident.K, U, U, 3) and lf.data.dtype == np.float32
    assert np.all(lf.data[:, ~lf.mask()] == 0)
    # Against our pixel-centre samples (the peer averages over pixels: about 2 % of bias here) ...
    assert rmse(lf, point) / mean < 0.05
    # ... and against our samples averaged over the pixel footprints (what the peer estimates): noise only.
    err = rmse(lf, pixel) / mean
    assert err < 0.04
    # Every mistake of orientation or lenslet order would show clearly.
    for wrong in (lf.data[:, :, ::-1], lf.data[:, ::-1], lf.data[::-1], lf.data[:, ::-1, ::-1],
                  lf.data.transpose(0, 2, 1, 3)):
        assert rmse(LightField(np.ascontiguousarray(wrong), lf.array), pixel) / mean > 5 * err


def test_02_rmse_falls_as_inverse_sqrt_spp(setup):
    incident, peer, point, pixel, mean = setup
    e_low = rmse(peer.render(64, seed=3), pixel)
    e_high = rmse(peer.render(1024, seed=4), pixel)
    assert 2.8 < e_low / e_high < 5.5                        # sqrt(1024 / 64) = 4


def test_03_spp_for_rmse(setup):
    incident, peer, point, pixel, mean = setup
    target = 0.15 * mean
    spp, seconds, err = spp_for_rmse(peer, pixel, target, max_spp=1024)
    assert spp & (spp - 1) == 0 and 1 <= spp <= 1024
    assert err <= target and seconds > 0
    assert err == pytest.approx(rmse(peer.render(spp, seed=0), pixel), rel=1e-3)
    if spp > 1:                                               # the smallest power of two that reaches it
        assert rmse(peer.render(spp // 2, seed=0), pixel) > target
    # An unreachable target: max_spp comes back as a lower bound, with its own RMSE above the target.
    spp, seconds, err = spp_for_rmse(peer, pixel, 1e-6 * mean, max_spp=16, repeats=2)
    assert spp == 16 and err > 1e-6 * mean and seconds > 0


def test_04_projector_texture_convention(variant):
    """T = L A cos^4 / pi in Mitsuba's image order: columns reversed (u descending), rows as in the grid."""
    incident = _incident("rect")
    tex = projector_texture(incident, 2)
    cos = incident.directions()[..., 2]
    expected = incident.data[2] * incident.array.aperture_area * (cos**4 / np.pi)[..., None]
    np.testing.assert_allclose(tex, expected[:, ::-1], rtol=1e-6)


def test_05_dark_lenslets_are_skipped(variant):
    incident = _incident("hex")
    incident.data[[1, 4]] = 0.0
    peer = PeerRenderer([_box()], incident, U, U, max_depth=2)
    assert len(peer.scene.emitters()) == incident.K - 2
    incident.data[...] = 0.0
    dark = PeerRenderer([_box()], incident, U, U, max_depth=1)
    assert len(dark.scene.emitters()) == 0
    assert np.all(dark.render(4).data == 0)


def test_06_rejects_bad_arguments(variant):
    incident = _incident("rect")
    with pytest.raises(ValueError):
        PeerRenderer([_box()], incident, 12, 8)
    with pytest.raises(ValueError):
        PeerRenderer([_box()], incident, U, U, max_depth=0)

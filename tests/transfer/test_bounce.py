"""Bounce algebra: differencing captures recovers the real scene's linear response to a projected light field."""

from __future__ import annotations

import numpy as np
import pytest

from lftransfer.lightfield import (CameraModel, LensletCodec, LightField, LightFieldDecoder, LightFieldEncoder,
                                   ProjectorModel, ResponseCurve)
from lftransfer.optics import LensArray, LensletDevice
from lftransfer.rig.base import Rig
from lftransfer.rig.requests import LFCapture, LFFrame, RigInfo, ViewCapture
from lftransfer.transfer.bounce import projector_gain, real_response

U = V = 8


class LinearRig:
    """A fake rig whose real scene is a known linear operator on light fields (no rendering).

    captured = direct + mix(emitted): every lenslet's light goes to another lenslet (a permutation), scaled by
    0.3 and mixed across colour channels by a 3 x 3 matrix.
    """

    def __init__(self, array, camera: CameraModel, projector: ProjectorModel):
        self.array = array
        self.camera = camera
        self.projector = projector
        self.cam_codec = LensletCodec(array, camera.device, U, V)
        self.prj_codec = LensletCodec(array, projector.device, U, V)
        self.decoder = LightFieldDecoder(array, camera, U, V)
        self.prj_encoder = LightFieldEncoder(array, projector, U, V)
        rng = np.random.default_rng(4)
        self.perm = rng.permutation(array.K)
        self.colour = np.array([[0.8, 0.1, 0.0], [0.1, 0.7, 0.1], [0.0, 0.2, 0.9]])
        self.direct = LightField.zeros(array, U, V)
        self.direct.data[...] = (0.2 + 0.1 * rng.random((array.K, 1, 1, 3))) * self.direct.mask()[None, :, :, None]
        self._pattern = None

    @property
    def info(self):
        return RigInfo(lf_camera=(self.camera.device.width, self.camera.device.height), lf_camera_bits=12,
                       projector=(self.projector.device.width, self.projector.device.height), projector_bits=8,
                       view=(8, 6), kind="fake")

    @property
    def projector_shape(self):
        return self.info.projector_shape

    def setup(self, request):
        pass

    def close(self):
        pass

    def respond(self, lf: LightField) -> LightField:
        out = LightField.zeros(self.array, U, V)
        out.data[self.perm] = 0.3 * lf.data @ self.colour.T
        return out

    def project(self, image):
        self._pattern = image

    def capture_lf(self, request=LFCapture()):
        emitted = self.prj_codec.image_to_lightfield(self.prj_encoder.emitted(self._pattern))
        captured = self.direct + self.respond(emitted)
        return LFFrame(codes=self.decoder.expose(self.cam_codec.lightfield_to_image(captured)), bits=12)

    def capture_view(self, request=ViewCapture()):
        raise NotImplementedError


@pytest.fixture()
def rig():
    array = LensArray(lattice="hex", rows=3, cols=4, pitch=0.0254, focal_length=0.0254)
    camera = CameraModel(LensletDevice.fronto_parallel(array, 320, 240), bits=12,
                         response=ResponseCurve((1.0, 1.2, 0.9)), exposure=0.8)
    projector = ProjectorModel(LensletDevice.fronto_parallel(array, 160, 120), bits=8,
                               response=ResponseCurve((2.2, 2.2, 2.2)), max_radiance=2.0)
    return LinearRig(array, camera, projector)


def _interior(lf: LightField) -> np.ndarray:
    """Samples well inside the lenslet cell (resampling there is exact for piecewise-constant data)."""
    u, v = np.meshgrid(lf.u, lf.v)
    return (np.abs(u) < 0.3) & (np.abs(v) < 0.3)


def test_01_differencing_recovers_linear_response(rig):
    rng = np.random.default_rng(0)
    ls = LightField.zeros(rig.array, U, V)
    ls.data[...] = 0.01 * rng.random((rig.array.K, 1, 1, 3)) * ls.mask()[None, :, :, None]  # weak, per lenslet
    rig.project(np.zeros((*rig.projector_shape, 3), np.uint8))
    assert isinstance(rig, Rig)
    direct = rig.decoder(rig.capture_lf().codes)
    gain = projector_gain(ls, rig.projector.max_radiance)
    assert gain > 50          # a weak light field is amplified into the projector's range
    encoder = LightFieldEncoder(rig.array, rig.projector, U, V)
    got = real_response(rig, rig.decoder, encoder, ls, direct, gain)
    want = rig.respond(ls)
    m = _interior(ls)
    err = np.abs(got.data[:, m] - want.data[:, m]).max()
    assert err < 0.02 * want.data.max(), err
    # Without the gain the 8-bit projector would round most of this light field to zero.
    unamplified = real_response(rig, rig.decoder, encoder, ls, direct, 1.0)
    assert np.abs(unamplified.data[:, m] - want.data[:, m]).max() > 5 * err


def test_02_gain_must_be_positive(rig):
    ls = LightField.zeros(rig.array, U, V)
    with pytest.raises(ValueError, match="gain"):
        real_response(rig, rig.decoder, LightFieldEncoder(rig.array, rig.projector, U, V), ls, ls, 0.0)


def test_03_projector_gain_fills_range():
    array = LensArray(lattice="rect", rows=2, cols=2, pitch=0.02, focal_length=0.02)
    lf = LightField.zeros(array, 4, 4)
    lf.data[1, 2, 3] = [0.1, 0.4, 0.2]
    assert projector_gain(lf, max_radiance=2.0, fill=0.5) == pytest.approx(2.5)
    assert projector_gain(LightField.zeros(array, 4, 4), max_radiance=2.0) == 1.0


def test_04_final_projection_sums_all_but_the_last_bounce():
    """The final frame projects Ls_0 + ... + Ls_{N-1}: the empty sum for N = 0, Ls_0 alone for N = 1."""
    from types import SimpleNamespace

    from lftransfer.transfer.bounce import final_projection

    array = LensArray(lattice="rect", rows=2, cols=2, pitch=0.02, focal_length=0.02)

    def lf(value: float) -> LightField:
        out = LightField.zeros(array, 4, 4)
        out.data[...] = value
        return out

    bounces = [SimpleNamespace(synthetic_lf=lf(v)) for v in (1.0, 2.0, 4.0)]
    assert final_projection(bounces[:1]).data.shape == (4, 4, 4, 3)
    assert not final_projection(bounces[:1]).data.any()                  # N = 0: nothing
    np.testing.assert_array_equal(final_projection(bounces[:2]).data, 1.0)
    np.testing.assert_array_equal(final_projection(bounces).data, 3.0)   # Ls_2 lights no further bounce


class _SpyRig:
    """A dark rig (tests/fakes.py) that keeps every image it was asked to project."""

    def __init__(self, scene):
        from tests.fakes import DarkRig

        self._rig = DarkRig(lf_camera=scene.rig.lf_camera, projector=scene.rig.projector, view=scene.view.resolution)
        self.info = self._rig.info
        self.projected: list[np.ndarray] = []

    def project(self, image) -> None:
        self._rig.project(image)
        self.projected.append(np.array(image))

    def __getattr__(self, name):
        return getattr(self._rig, name)


@pytest.mark.parametrize("bounces", [0, 1])
def test_05_zero_bounces_project_nothing(variant, tmp_path, bounces):
    """``--bounces 0``: the projector never shows anything but black, and the final real view is the direct one;
    with one bounce Ls_0 (lit by the virtual point light) is projected in the final frame."""
    from lftransfer.rig.model import nominal_rig
    from lftransfer.scenes import load_scene
    from lftransfer.transfer.bounce import TransferSettings, run_transfer
    from tests.small import write_tiny_scene

    scene = load_scene(write_tiny_scene(tmp_path / "tiny.toml", view=(32, 24)))
    rig = _SpyRig(scene)
    result = run_transfer(rig, nominal_rig(scene.rig), scene.synthetic_part(),
                          TransferSettings(bounces=bounces, angular_samples=8, lf_spp=1, view_spp=1))
    assert result.bounces[0].synthetic_lf.data.max() > 0          # there is something that could be projected
    if bounces == 0:
        assert not any(image.any() for image in rig.projected), "a pattern was projected with --bounces 0"
        assert not result.projected_lf.data.any() and not result.projected_image.any()
        assert result.clipped_fraction == 0.0
        np.testing.assert_array_equal(result.real_view, result.real_view_direct)
    else:
        np.testing.assert_array_equal(result.projected_lf.data, result.bounces[0].synthetic_lf.data)
        assert result.projected_image.any() and any(image.any() for image in rig.projected)


def test_06_depth_projection_measures_the_real_scene_and_prefilters(variant, tmp_path):
    """``projection = "depth"`` on a simulated rig: one extra frame with the projector white, a depth found on the
    real block (its centre 8 cm from the array, the faces turned to it 4 to 8 cm; measured: 67 % of the entries get
    a depth, median 6.2 cm, 10th to 90th percentile 4.1 to 8.1 cm), every projected light field prefiltered; the
    box projection takes neither step."""
    from lftransfer.rig.model import nominal_rig
    from lftransfer.scenes import load_scene
    from lftransfer.sim.rig import SimRig
    from lftransfer.transfer.bounce import TransferSettings, run_transfer
    from tests.small import write_tiny_scene

    scene = load_scene(write_tiny_scene(tmp_path / "tiny.toml", view=(32, 24)))
    results = {}
    for projection in ("box", "depth"):
        rig = SimRig(scene)
        settings = TransferSettings(bounces=1, angular_samples=8, lf_spp=2, view_spp=1, projection=projection)
        results[projection] = run_transfer(rig, nominal_rig(scene.rig), scene.synthetic_part(), settings)
    box, depth = results["box"], results["depth"]
    assert box.depth is None and "measure_depth" not in box.timings_s and "prefilter" not in box.timings_s
    assert {"measure_depth", "prefilter"} <= set(depth.timings_s)
    found = np.isfinite(depth.depth)
    assert found.mean() > 0.5
    assert 0.05 < np.median(depth.depth[found]) < 0.075
    assert 0.035 < np.percentile(depth.depth[found], 10) and np.percentile(depth.depth[found], 90) < 0.09
    assert (depth.projected_lf.data >= 0).all()
    assert not np.allclose(depth.projected_lf.data, box.projected_lf.data)

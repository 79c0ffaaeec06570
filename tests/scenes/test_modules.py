"""The scene format's modules after the split: rotations through optics.geometry (the old hand-built formula's
results), render defaults from lftransfer.choices, and every name still importable from lftransfer.scenes.format."""

from __future__ import annotations

from typing import get_args

import numpy as np
import pytest

from lftransfer import choices
from lftransfer.optics.geometry import rotation_matrix
from lftransfer.scenes import ObjectConfig, RenderConfig, RigConfig


def _old_rotation(rotate_deg) -> np.ndarray:
    """The scene format's rotation before it used scipy: R = Rz @ Ry @ Rx (degrees), built by hand."""
    ax, ay, az = np.radians(np.asarray(rotate_deg, dtype=np.float64))
    cx, sx, cy, sy, cz, sz = np.cos(ax), np.sin(ax), np.cos(ay), np.sin(ay), np.cos(az), np.sin(az)
    rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return rz @ ry @ rx


def test_rotation_matrix_equals_the_old_formula_on_random_angles():
    rng = np.random.default_rng(20240611)
    angles = np.concatenate([rng.uniform(-720.0, 720.0, (500, 3)),
                             rng.choice([-270.0, -180.0, -90.0, 0.0, 90.0, 180.0, 270.0], (100, 3))])
    for a in angles:
        R = rotation_matrix(a)
        assert R.shape == (3, 3) and R.dtype == np.float64
        np.testing.assert_allclose(R, _old_rotation(a), rtol=0, atol=1e-15)
    obj = ObjectConfig(name="b", shape="box", size=[0.1, 0.2, 0.3], rotate_deg=[10.0, -35.0, 200.0])
    np.testing.assert_allclose(obj.rotation(), _old_rotation(obj.rotate_deg), rtol=0, atol=1e-15)


def test_render_and_rig_defaults_are_the_choices_module_s():
    r, rig = RenderConfig(), RigConfig()
    assert r.lighting_model == choices.DEFAULT_LIGHTING_MODEL
    assert r.reconstruction == choices.DEFAULT_RECONSTRUCTION
    assert r.projection == choices.DEFAULT_PROJECTION
    assert r.window == choices.DEFAULT_WINDOW
    assert r.spp == choices.DEFAULT_SPP and r.gt_spp == choices.DEFAULT_GT_SPP
    assert r.aperture_samples == choices.DEFAULT_APERTURE_SAMPLES
    assert rig.angular_samples == choices.DEFAULT_ANGULAR_SAMPLES
    fields = RenderConfig.model_fields
    assert set(get_args(fields["lighting_model"].annotation)) == set(choices.LIGHTING_MODELS)
    assert get_args(fields["reconstruction"].annotation) == choices.RECONSTRUCTIONS
    assert get_args(fields["projection"].annotation) == choices.PROJECTIONS
    assert get_args(fields["window"].annotation) == choices.WINDOWS


@pytest.mark.parametrize("name", [
    "SceneError", "RigConfig", "ViewConfig", "LightConfig", "EffectConfig", "RenderConfig", "DiffuseMaterial",
    "GlossyMaterial", "MetalMaterial", "EmitterMaterial", "Material", "ObjectConfig", "Keyframe",
    "AnimationConfig", "SceneConfig", "SyntheticScene", "check_synthetic", "load_scene", "builtin_scene",
    "builtin_scenes", "with_overrides", "read_mesh", "read_texture", "TEXTURED_SHAPES", "CYLINDER_SECTIONS",
    "MAX_LIGHTS", "RealObject", "SyntheticObject", "ShapeName", "Float", "PosFloat", "NonNegFloat", "Unit",
    "PosInt", "Vec3", "PosVec3", "NonNegVec3", "RGBUnit", "Size2",
])
def test_format_module_keeps_every_name(name):
    import lftransfer.scenes as package
    import lftransfer.scenes.format as fmt

    assert name in fmt.__all__ and hasattr(fmt, name)
    if name in package.__all__:
        assert getattr(package, name) is getattr(fmt, name)

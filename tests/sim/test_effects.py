"""Effects measured on view images (lftransfer.sim.effects): the reflection's added radiance and the shadow's
contrast and penumbra width on synthetic images with known answers, and the object pixels and their surface areas
against a flat rectangle's analytic area."""

from __future__ import annotations

import numpy as np
import pytest

from lftransfer.scenes import SceneConfig
from lftransfer.sim.effects import ObjectPixels, measure_effect, object_distance, object_pixels

H, W = 96, 128
PIXEL_AREA = 1e-6            # 1 mm^2 per pixel


def _flat(mask: np.ndarray) -> ObjectPixels:
    return ObjectPixels(mask=mask, area_m2=np.where(mask, PIXEL_AREA, 0.0), factor=1)


def _shadowed(contrast: float, r_umbra: float, r_outer: float, base: float = 2.0):
    """An image lit at ``base`` everywhere, darkened by a round shadow: ``contrast`` inside r_umbra (pixels),
    falling linearly to 0 at r_outer."""
    y, x = np.mgrid[0:H, 0:W].astype(np.float64)
    r = np.hypot(x - W / 2, y - H / 2)
    s = contrast * np.clip((r_outer - r) / (r_outer - r_umbra), 0.0, 1.0)
    without = np.full((H, W, 3), base, np.float32)
    return (without * (1.0 - s)[..., None]).astype(np.float32), without


def test_01_reflection_is_the_mean_radiance_added_over_the_object():
    rng = np.random.default_rng(1)
    without = rng.random((H, W, 3)).astype(np.float32)
    mask = np.zeros((H, W), bool)
    mask[20:60, 30:90] = True
    image = without.copy()
    image[mask] += np.array([0.3, 0.6, 0.9], np.float32)
    image[~mask] += 5.0                                     # light added elsewhere is not the object's
    m = measure_effect("reflection", image, without, _flat(mask))
    assert m.added_radiance == pytest.approx(0.6, rel=1e-5)
    assert m.pixels == mask.sum() and m.contrast is None


def test_02_shadow_contrast_and_penumbra_of_a_round_shadow():
    """A linear edge from r1 to r2: s passes 90 % of the contrast at r1 + 0.1 (r2 - r1) and 10 % at
    r2 - 0.1 (r2 - r1), so the penumbra is 0.8 (r2 - r1) pixels of 1 mm."""
    for contrast, r1, r2 in ((0.9, 10.0, 30.0), (0.4, 15.0, 20.0)):
        image, without = _shadowed(contrast, r1, r2)
        m = measure_effect("shadow", image, without, _flat(np.ones((H, W), bool)))
        assert m.contrast == pytest.approx(contrast, rel=1e-6)
        assert m.penumbra_m * 1000 == pytest.approx(0.8 * (r2 - r1), abs=0.6)
        half = r2 - 0.5 / contrast * (r2 - r1) if contrast >= 0.5 else 0.0   # s = 0.5 there
        assert m.area_m2 == pytest.approx(np.pi * half ** 2 * PIXEL_AREA, rel=0.03, abs=PIXEL_AREA)


def test_03_sharper_shadow_has_a_narrower_penumbra_and_noise_makes_no_shadow():
    wide = measure_effect("shadow", *_shadowed(0.8, 5.0, 35.0), _flat(np.ones((H, W), bool)))
    sharp = measure_effect("shadow", *_shadowed(0.8, 18.0, 22.0), _flat(np.ones((H, W), bool)))
    assert sharp.penumbra_m < 0.3 * wide.penumbra_m
    rng = np.random.default_rng(2)
    without = np.full((H, W, 3), 1.0, np.float32)
    noisy = (without * (1 + 0.05 * rng.standard_normal((H, W, 1)))).astype(np.float32)
    control = measure_effect("shadow", noisy, without, _flat(np.ones((H, W), bool)))
    assert control.contrast < 0.1                           # 5 % noise per pixel, averaged over 3 x 3


def test_04_unlit_pixels_are_not_measured():
    image, without = _shadowed(0.9, 10.0, 30.0)
    without[:, : W // 2] = 0.0                              # the left half gets no light at all
    image[:, : W // 2] = 0.0
    m = measure_effect("shadow", image, without, _flat(np.ones((H, W), bool)))
    assert m.pixels == H * (W - W // 2)
    assert measure_effect("shadow", image * 0, without * 0, _flat(np.ones((H, W), bool))).contrast is None
    with pytest.raises(ValueError, match="kind"):
        measure_effect("glow", image, without, _flat(np.ones((H, W), bool)))


def _card_scene(occluder: bool) -> SceneConfig:
    """A 10 x 8 cm real card facing a view camera 0.5 m away, and optionally a synthetic box hiding part of it."""
    synthetic = [{"name": "box", "shape": "box", "size": [0.04, 0.04, 0.02], "translate": [0.0, 0.0, -0.02],
                  "material": {"albedo": [0.5, 0.5, 0.5]}}] if occluder else \
        [{"name": "far", "shape": "sphere", "radius": 0.01, "translate": [0.3, 0.3, -0.3]}]
    return SceneConfig.model_validate({
        "view": {"resolution": [256, 192], "origin": [0.0, 0.0, -0.45], "target": [0.0, 0.0, 0.0],
                 "up": [0.0, 1.0, 0.0], "fov_deg": 30.0},
        "light": {"position": [0.3, 0.1, 0.0], "intensity": [1, 1, 1]},
        "real": [{"name": "card", "shape": "rectangle", "size": [0.10, 0.08], "translate": [0.0, 0.0, 0.05],
                  "rotate_deg": [0.0, 180.0, 0.0]}],
        "synthetic": synthetic})


def test_05_object_pixels_cover_the_card_with_its_area():
    """The areas of the pixels wholly on the card add up to the card's area less a rim of partly covered pixels;
    a synthetic box in front takes its pixels away (about its 4 x 4 cm face projected onto the card)."""
    px = object_pixels(_card_scene(False), "card")
    total = px.area_m2.sum()
    assert 0.95 * 0.008 < total <= 0.008
    assert px.mask.sum() > 0 and (px.area_m2[~px.mask] == 0).all()
    hidden = object_pixels(_card_scene(True), "card")
    lost = total - hidden.area_m2.sum()
    face = 0.04 * 0.04 * (0.5 / 0.43) ** 2                  # the box's front face at z = -0.03, cast onto the card
    assert lost == pytest.approx(face, rel=0.1)
    with pytest.raises(ValueError, match="one object named"):
        object_pixels(_card_scene(False), "nothing")


def test_06_distance_between_origins():
    scene = _card_scene(False)
    assert object_distance(scene, "card", "far") == pytest.approx(np.linalg.norm([0.3, 0.3, -0.35]))

"""The ray-casting floor: the rays a renderer casts, recorded as cast, and one intersection each timed."""

from __future__ import annotations

import numpy as np
import pytest

from lftransfer.runs.bench.floor import RayBatch, RayRecorder, ray_floor
from lftransfer.lightfield import LightField
from lftransfer.optics import LensArray
from lftransfer.render.fast import CachedRenderer
from lftransfer.render.lights import PointLight
from tests.runs.bench.test_peer import _box


def test_01_records_the_rays_as_cast_and_unwraps(variant):
    renderer = CachedRenderer([_box()])
    array = LensArray(lattice="hex", rows=2, cols=3, pitch=0.0254, focal_length=0.0254)
    light = PointLight(np.array([0.3, 0.1, 0.0]), np.array([1.0, 1.0, 1.0]))
    with RayRecorder(renderer) as rec:
        renderer.render_lightfield(array, [light], 6, 6, model="area", spp=2)
    assert "render_samples" not in renderer.__dict__                    # the class's method again
    (batch,) = rec.batches
    entries = array.K * int(LightField.zeros(array, 6, 6).mask().sum())  # the entries with data have rays
    assert batch.count == entries * 2 and batch.origins.shape == batch.directions.shape == (batch.count, 3)
    timing = ray_floor(renderer.objects, rec.batches, repeats=2, renderer_scene=renderer.scene)
    assert timing.rays == (batch.count,) and timing.repeats == 2 and len(timing.batch_ms) == 1
    assert timing.ms > 0 and timing.ms == min(timing.scene_geometry_ms, timing.renderer_geometry_ms)
    alone = ray_floor(renderer.objects, rec.batches, repeats=1)
    assert alone.geometry == "scene" and alone.renderer_geometry_ms is None


def test_02_rejects_nothing_to_cast(variant):
    with pytest.raises(ValueError, match="no rays"):
        ray_floor([_box()], [])
    rays = RayBatch(np.zeros((4, 3), np.float32), np.tile(np.float32([0, 0, -1]), (4, 1)))
    with pytest.raises(ValueError, match="repeats"):
        ray_floor([_box()], [rays], repeats=0)

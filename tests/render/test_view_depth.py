"""A view render's depth is the mean distance of the rays that hit, also where only some of a pixel's rays do
(lftransfer.render.renderer.mean_depth): a silhouette pixel of a plane 0.5 m away is 0.5 m away, not nearer.

The depth once divided the rays' summed distance (misses counting 0) by all of a pixel's rays, so a pixel a fifth
covered read a fifth of the distance: the synthetic objects' edges came out in front of everything, and the
ground truth's real depth put a real object's fringe in front of the synthetic ones. The negative control: the
partly covered pixels' mean over all their rays, misses as 0, is that far off.
"""

from __future__ import annotations

import numpy as np

from lftransfer.backend import mitsuba
from lftransfer.optics.geometry import pixel_rays
from lftransfer.render.camera import sensor_dict
from lftransfer.render.renderer import HalfSpaceRenderer
from lftransfer.scenes.models import ViewConfig
from lftransfer.scenes.objects import ObjectConfig


def test_01_a_silhouette_pixel_is_as_far_as_the_surface():
    view = ViewConfig(resolution=(48, 32), origin=[0.0, 0.0, 0.5], target=[0.0, 0.0, 0.0], up=[0.0, 1.0, 0.0],
                      fov_deg=30.0)
    plane = ObjectConfig(name="plane", shape="rectangle", size=[0.1, 0.2], translate=[0.013, 0.0, 0.0])
    w, h = view.resolution
    sensor = mitsuba().load_dict(sensor_dict(view.origin, view.target, view.up, view.fov_deg, w, h, spp=64))
    image = HalfSpaceRenderer([plane], max_depth=1).render_view(sensor, w, h, [], spp=64)
    ys, xs = np.mgrid[0:h, 0:w]
    _c, rays = pixel_rays(view, np.stack([xs.ravel(), ys.ravel()], -1))
    along = (0.5 / -rays[:, 2]).reshape(h, w)                     # where each pixel's centre ray meets z = 0
    partial = (image.alpha > 0.1) & (image.alpha < 0.9)
    assert partial.sum() >= 2 * h - 4                             # the plane's two vertical edges, every row
    covered = image.alpha > 0
    np.testing.assert_allclose(image.depth[covered], along[covered], rtol=0.01)
    assert np.all(np.isinf(image.depth[~covered]))
    # negative control: the mean over all of a partly covered pixel's rays, misses as 0, is far nearer
    assert np.all(image.depth[partial] * image.alpha[partial] < 0.92 * along[partial])

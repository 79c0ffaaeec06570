"""The view camera: a pinhole camera that looks along the interface and sees both half-spaces.

The geometry is Mitsuba's own ``perspective`` sensor, so that the renderer, the simulated rig and the
path-traced ground truth (which renders through the same sensor) agree to the pixel.
"""

from __future__ import annotations

import numpy as np

from lftransfer.backend import mitsuba


def sensor_dict(origin, target, up, fov_deg: float, width: int, height: int, *, spp: int = 1) -> dict:
    """Mitsuba dict of the view camera (horizontal field of view ``fov_deg``, box pixel filter, RGBA film)."""
    mi = mitsuba()
    return {
        "type": "perspective",
        "fov": float(fov_deg),
        "fov_axis": "x",
        "to_world": mi.ScalarTransform4f().look_at(origin=list(map(float, origin)), target=list(map(float, target)),
                                                   up=list(map(float, up))),
        "film": {"type": "hdrfilm", "width": int(width), "height": int(height), "rfilter": {"type": "box"},
                 "pixel_format": "rgba"},
        "sampler": {"type": "independent", "sample_count": int(spp)},
    }


def view_rays(sensor, width: int, height: int, spp: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Stratified primary rays through every pixel of the view camera.

    Args:
        sensor: a Mitsuba perspective sensor (from :func:`sensor_dict`).
        width, height: image size in pixels.
        spp: rays per pixel, jittered on a sqrt(spp) x sqrt(spp) grid when spp is a square.
        seed: jitter seed.

    Returns:
        origins (H*W*spp, 3) and directions (H*W*spp, 3) float32, pixel-major (spp fastest).
    """
    mi = mitsuba()
    rng = np.random.default_rng(seed)
    n = width * height * spp
    s = np.arange(spp)
    side = int(round(np.sqrt(spp)))
    if side * side == spp:
        jx = (s % side + rng.random((width * height, spp))) / side
        jy = (s // side + rng.random((width * height, spp))) / side
    else:
        jx = rng.random((width * height, spp))
        jy = rng.random((width * height, spp))
    pix = np.arange(width * height)
    px = ((pix % width)[:, None] + jx) / width
    py = ((pix // width)[:, None] + jy) / height
    ray, _ = sensor.sample_ray(mi.Float(0.0), mi.Float(0.5),
                               mi.Point2f(px.ravel().astype(np.float32), py.ravel().astype(np.float32)),
                               mi.Point2f(0.5, 0.5))
    # Mitsuba starts camera rays at the near clip plane; ours start at the centre of projection, so that hit
    # distances are depths from the camera.
    centre = np.array(sensor.world_transform().translation(), dtype=np.float32).ravel()[:3]
    d = np.array(ray.d, dtype=np.float32)
    return np.ascontiguousarray(np.broadcast_to(centre, (n, 3))), np.ascontiguousarray(d.T)

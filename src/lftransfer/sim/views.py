"""Test light fields of known depth rendered on the simulated rig (``lft sim views``): a grid of sub-aperture views of
the real scene, laid out as camera arrays and the 4D light field benchmark distribute them
(:mod:`lftransfer.lightfield.view_grid`), with the true disparity and depth of the centre view, for ``lft depth``.

The centre camera is the scene's view camera. Camera (s, t) of an N x N grid stands ``(s - c) B`` to its right and
``(t - c) B`` below it (c = N // 2, B the baseline), looking the same way, its image shifted by ``(s - c) p`` and
``(t - c) p`` pixels (a whole number ``p``: the sensor shift that puts the focus plane at ``Z0 = f B / p``, f the focal
length in pixels). A point at depth z along the optical axis then has the benchmark's disparity
``d = B f (1 / z - 1 / Z0)`` pixels per view step (positive nearer than the focus plane) and appears in view (s, t)
at the centre view's position less ``(s - c, t - c) d``. Each view is rendered wider by the largest shift and
cropped, so the shift is exact. The views are the real objects in the scene's lights, projector black (what the
simulated rig's view camera photographs), as grey in [0, 1] (the mean of R, G and B over the brightest 0.5 % of the
grid's pixels); the truth is the centre view's distances (the mean of its rays that hit), nothing seen reading as
infinitely far (disparity ``-p``).
"""

from __future__ import annotations

import numpy as np

from lftransfer.lightfield.view_grid import ViewGrid

__all__ = ["render_view_grid"]


def render_view_grid(scene, *, n: int = 9, baseline_m: float = 0.002, shift_px: int = 1, spp: int = 16,
                     truth_seed: int | None = 0) -> tuple[ViewGrid, np.ndarray, np.ndarray]:
    """Render an ``n`` x ``n`` grid of views of ``scene``'s real objects around its view camera (module docstring).

    Args:
        scene: the whole scene (its real objects, lights and view camera; the hidden truth ``truth_seed`` draws).
        n: views per side (odd, >= 3).
        baseline_m: distance between neighbouring cameras, metres.
        shift_px: the sensor shift per view step, pixels (>= 0; 0 puts the focus plane at infinity).
        spp: rays per pixel.
        truth_seed: seed of the hidden truth (how the rig and the lights really are), or None for the files'.

    Returns:
        (the grid, (H, W) float32 true disparity of the centre view, pixels per view step, (H, W) float32 true
        depth along the optical axis, metres; inf where nothing is seen).
    """
    from lftransfer.optics.geometry import pixel_rays, view_camera
    from lftransfer.scenes.models import ViewConfig
    from lftransfer.sim.oracle import open_simulated_rig

    if n < 3 or n % 2 == 0:
        raise ValueError(f"n: views per side must be odd and at least 3, got {n}")
    if not baseline_m > 0 or shift_px < 0 or spp < 1:
        raise ValueError(f"need baseline_m > 0, shift_px >= 0 and spp >= 1, got {baseline_m}, {shift_px}, {spp}")
    rig, _oracle = open_simulated_rig(scene, truth_seed)
    view = scene.view
    w, h = view.resolution
    K, R, _t = view_camera(view)
    f_px = K[0, 0]
    c = n // 2
    margin = c * shift_px
    wide_fov = float(np.degrees(2.0 * np.arctan((w + 2 * margin) / 2.0 / f_px)))
    right, down, fwd = R                            # the rotation's rows: x right, y down, z forward (world)
    views = np.empty((n, n, h, w), np.float32)
    centre_depth = None
    for t in range(n):
        for s in range(n):
            offset = (s - c) * baseline_m * right + (t - c) * baseline_m * down
            cam = ViewConfig(resolution=(w + 2 * margin, h + 2 * margin),
                             origin=tuple(np.asarray(view.origin, float) + offset),
                             target=tuple(np.asarray(view.target, float) + offset), up=tuple(view.up), fov_deg=wide_fov)
            image = rig.photograph_from(cam, spp)
            x0, y0 = margin - (s - c) * shift_px, margin - (t - c) * shift_px
            views[t, s] = image.rgb[y0:y0 + h, x0:x0 + w].mean(-1)
            if s == c and t == c:
                centre_depth = image.depth[y0:y0 + h, x0:x0 + w]
    bright = float(np.percentile(views, 99.5))
    views = np.clip(views / bright, 0.0, 1.0) if bright > 0 else views
    ys, xs = np.mgrid[0:h, 0:w]
    rays = pixel_rays(view, np.stack([xs.ravel(), ys.ravel()], -1))[1].reshape(h, w, 3)
    z = np.where(np.isfinite(centre_depth), centre_depth * (rays @ fwd), np.inf)
    focus = f_px * baseline_m / shift_px if shift_px else np.inf
    disparity = baseline_m * f_px * (1.0 / z - 1.0 / focus)
    finite = disparity[np.isfinite(z)]
    lo, hi = (float(finite.min()), float(finite.max())) if finite.size else (-1.0, 1.0)
    lo, hi = min(lo, -float(shift_px)), max(hi, lo + 1e-3)
    grid = ViewGrid(views, baseline_m=baseline_m, focal_px=float(f_px), focus_m=float(focus),
                    disp_min=lo - 0.2 * (hi - lo), disp_max=hi + 0.2 * (hi - lo))
    return grid, disparity.astype(np.float32), z.astype(np.float32)

"""A study of the projector's side: can a prefilter of the projected light field make the irradiance a real
surface receives what the synthetic scene would have sent it, better than the box prefilter?

A projector lenslet sends one radiance per direction over its whole aperture, so the box prefilter (each entry the
average of the synthetic light over the aperture) delivers, at a real point, every direction's light blurred over
a lenslet. Given where each ray lands on the real surface, a better light field exists: bin the landing points
(``BIN`` metres), and choose the projected entries P so that every bin receives the light the synthetic scene sends
along the same rays,

    min_P  sum_bins (sum_{rays in bin} w_r (P[pixel(r)] - Ls(r)))^2  +  (DAMP * s)^2 |P - P_box|^2,   P >= 0,

with ``w_r`` a ray's etendue weight, ``Ls(r)`` the synthetic radiance along it (one ray per aperture point of
every projector pixel), ``s`` the RMS column norm, solved by LSQR around the box light field and clipped at zero.
Each lenslet keeps the power of its box entries (the prefilter moves light between directions, it does not add
any). The landing points come from:

- ``true geometry``: the simulator's real objects (an oracle: what the method gives with perfect depth);
- ``measured depth``: a depth per light field sample along its centre ray, measured from the rig's own images
  (the projector shows white, the LF camera captures, the direct frame is subtracted, and a plane sweep finds the
  depth where neighbouring lenslets see the same radiance: :func:`plane_sweep`); each aperture point's ray lands
  on the plane of its sample's depth.

Variants run Fig. 4 and three scenes of this folder (quarter resolution, true rig model, truth seed 2, the linear
reconstruction, 2 bounces, ground truth 8192 samples per pixel) and print ``cross_by_side`` as
``where_the_error_is.py`` does.

``--fig5`` measures instead the planet's shadow on the head in Fig. 5 (quarter resolution, converged 2-bounce
transfers at frames 24, 32 and 40, true rig model, truth seed 0) with the box light field and the prefilter from
the true geometry, beside the ground truth's (:mod:`lftransfer.sim.effects`): the projector carries the sun's
light to the head, so the shadow's edge is where the aperture's blur shows.

Run: python benchmarks/reconstruction/projector_prefilter.py [--fig5]   (about 1 minute once the ground truths
are cached; --fig5 about 5). The tables are in docs/architecture.md ("The projector's side").
"""

from __future__ import annotations

from contextlib import contextmanager
from dataclasses import replace
from pathlib import Path

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import lsqr
from scipy.spatial import cKDTree

from lftransfer.app.bench.step import transfer_settings
from lftransfer.app.pipeline import RunOptions, knowledge, open_rig, quick_scene
from lftransfer.lightfield.lightfield import LightField
from lftransfer.render.renderer import lightfield_rays
from lftransfer.rig.requests import RealScene
from lftransfer.scenes import builtin_scene, load_scene
from lftransfer.sim.verify import evaluate, render_ground_truth
from lftransfer.transfer.bounce import run_transfer
from lftransfer.transfer.synthetic_side import SyntheticSide

HERE = Path(__file__).parent
GT_SPP = 8192
BIN = 0.004            # m, landing bins
DAMP = 0.3             # pull towards the box light field, relative to the RMS column norm
RAYS = 8               # aperture points per projector pixel
SWEEP = 1.0 / np.linspace(1.0 / 0.02, 1.0 / 0.4, 64)     # m, candidate depths (uniform in 1 / z)


def plane_sweep(lf: LightField, depths: np.ndarray, neighbours: int = 18) -> np.ndarray:
    """Depth along each sample's centre ray where neighbouring lenslets see the same radiance.

    Args:
        lf: the real scene's light field, lit (K, V, U, 3).
        depths: (M,) candidate depths, m.
        neighbours: lenslets compared with each sample's own (nearest first).

    Returns:
        (K, V, U) float64 depth, m; NaN where the sample is dark (below 2 % of the 99th percentile) or fewer than
        two neighbours see the candidate points.
    """
    array = lf.array
    a, f = array.half_width, array.focal_length
    mask = lf.mask()
    lum = lf.data.mean(-1)
    lit = (lum > 0.02 * np.percentile(lum[:, mask], 99)) & mask[None]
    ks, js, is_ = np.nonzero(lit)
    own = lf.data[ks, js, is_]
    uv = np.stack([lf.u[is_], lf.v[js]], -1)
    centres = array.centres
    nb = cKDTree(centres).query(centres, neighbours + 1)[1][:, 1:]
    cost = np.full((len(depths), len(ks)), np.inf)
    for m, z in enumerate(depths):
        points = centres[ks] + z * uv
        acc, seen = np.zeros(len(ks)), np.zeros(len(ks))
        for q in range(neighbours):
            k2 = nb[ks, q]
            uv2 = (points - centres[k2]) / z
            ok = (np.abs(uv2) <= a).all(-1) & array.in_cell(-f * uv2)
            other = lf.lookup(np.where(ok, k2, -1), np.concatenate([uv2, np.ones((len(ks), 1))], -1))
            acc += np.where(ok, np.abs(other - own).sum(-1) / (other.sum(-1) + own.sum(-1) + 1e-6), 0.0)
            seen += ok
        cost[m] = np.where(seen >= 2, acc / np.maximum(seen, 1), np.inf)
    depth = np.full(lum.shape, np.nan)
    found = np.isfinite(cost.min(0))
    depth[ks[found], js[found], is_[found]] = depths[np.argmin(cost, 0)[found]]
    return depth


def measured_depth(opened, side: SyntheticSide) -> np.ndarray:
    """(K, V, U) depth measured through the rig: white projected, captured, the direct frame subtracted."""
    rig, model = opened.rig, side.model
    rig.setup(RealScene(time_s=0.0))
    opened.start_frame(0)
    rig.project(rig.info.black())
    black = side.decoder(rig.capture_lf().codes)
    U = side.settings.angular_samples
    white = LightField.zeros(model.array, U, U)
    white.data[:] = 0.5 * model.projector.max_radiance * white.mask()[None, :, :, None]
    rig.project(side.encoder(white))
    lit = side.decoder(rig.capture_lf().codes) - black
    rig.project(rig.info.black())
    return plane_sweep(lit, SWEEP)


def prefiltered(box: LightField, renderer, lights, seed: int, landing) -> LightField:
    """The projected light field that best gives each landing bin the synthetic light of its rays (module
    docstring); ``landing(origins, directions, pixel)`` -> (hit (R,), points (R, 3))."""
    array, mask = box.array, box.mask()
    K, V, U = box.data.shape[:3]
    n = int(mask.sum())
    origins, looking = lightfield_rays(array, U, V, spp=RAYS, seed=seed + 7)     # looking into z < 0
    data = np.broadcast_to(mask, (K, V, U)).reshape(-1)
    pixel = np.full(K * V * U, -1)
    pixel[data] = np.arange(K * n)                               # (k, j, i) -> its index among the data entries
    pixel = np.repeat(pixel, RAYS)
    ours = pixel >= 0
    origins, looking, pixel = origins[ours], looking[ours], pixel[ours]
    radiance, _, _ = renderer.render_rays(origins, looking, lights, seed=seed + 11)
    hit, points = landing(origins, -looking, pixel)
    w = np.tile(box.solid_angle_weights()[mask], K)[pixel[hit]] / RAYS
    cells = np.floor(points[hit] / BIN).astype(np.int64)
    bins = np.unique(cells, axis=0, return_inverse=True)[1].ravel()
    target = np.zeros((bins.max() + 1, 3))
    np.add.at(target, bins, w[:, None] * radiance[hit])
    M = sp.csr_matrix((w, (bins, pixel[hit])), shape=(len(target), K * n))
    p0 = box.data[:, mask].reshape(-1, 3).astype(np.float64)
    norms = np.sqrt(np.asarray(M.multiply(M).sum(0)).ravel())
    damp = DAMP * np.sqrt(np.mean(norms[norms > 0] ** 2))
    p = np.stack([np.maximum(p0[:, c] + lsqr(M, target[:, c] - M @ p0[:, c], damp=damp, iter_lim=200)[0], 0.0)
                  for c in range(3)], -1)
    wq = box.solid_angle_weights()[mask]
    p, p0 = p.reshape(K, n, 3), p0.reshape(K, n, 3)
    kept, now = np.einsum("kpc,p->kc", p0, wq), np.einsum("kpc,p->kc", p, wq)
    p *= np.where(now > 0, kept / np.maximum(now, 1e-12), 1.0)[:, None, :]
    out = box.copy()
    data = out.data.copy()
    data[:, mask] = p
    out.data[...] = data
    return out


@contextmanager
def projecting(landing):
    """Every outgoing light field the transfer renders goes through :func:`prefiltered` while inside."""
    plain = SyntheticSide.render

    def render(self, lights, seed, timer=None):
        ls, view = plain(self, lights, seed, timer)
        return prefiltered(ls, self.renderer, lights, seed, landing), view

    SyntheticSide.render = render
    try:
        yield
    finally:
        SyntheticSide.render = plain


def true_landing(opened, time_s: float = 0.0):
    real = opened.rig._real_renderer(time_s)        # the simulator's hidden real objects: the oracle

    def landing(origins, dirs, _pixel):
        _, hit, dist = real.render_rays(origins, dirs, [])
        return hit, origins + dist[:, None] * dirs
    return landing


def depth_landing(depth: np.ndarray, mask: np.ndarray):
    z = depth[:, mask].reshape(-1)

    def landing(origins, dirs, pixel):
        zr = z[pixel]
        hit = np.isfinite(zr)
        return hit, origins + np.where(hit, zr, 0.0)[:, None] * dirs / dirs[:, 2:3]
    return landing


def fig5_shadow() -> None:
    from lftransfer.app.effects import _without
    from lftransfer.composite import composite
    from lftransfer.sim.effects import measure_effect, object_distance, object_pixels

    scene = quick_scene(load_scene(builtin_scene("fig5")))
    effect = scene.effect
    print("| frame | planet to head (m) | projected light field | contrast | penumbra (mm) | area taking half the "
          "light (cm^2) |")
    print("|---|---|---|---|---|---|")
    for frame in (24, 32, 40):
        opened = open_rig(scene, RunOptions(truth_seed=0))
        known = knowledge(opened, scene, "oracle")
        t = frame / scene.animation.fps
        world = opened.world.at(t)
        pixels = object_pixels(world, effect.on)
        distance = object_distance(world, effect.on, effect.by)
        gt = render_ground_truth(world, spp=scene.render.gt_spp).image
        gt_without = render_ground_truth(_without(world, effect.by), spp=scene.render.gt_spp).image
        rows = [("ground truth", measure_effect("shadow", gt, gt_without, pixels))]
        settings = replace(transfer_settings(scene), bounces=2, bounce_views=False)
        for variant in ("box", "true geometry"):
            images = []
            for synthetic in (known.scene, _without(known.scene, effect.by)):
                opened.start_frame(frame)
                if variant == "box":
                    r = run_transfer(opened.rig, known.model, synthetic, settings, time_s=t)
                else:
                    with projecting(true_landing(opened, t)):
                        r = run_transfer(opened.rig, known.model, synthetic, settings, time_s=t)
                images.append(composite(r.synthetic_view.rgb, r.synthetic_view.alpha, r.real_view))
            rows.append((variant, measure_effect("shadow", images[0], images[1], pixels)))
        for name, m in rows:
            pen = f"{1e3 * m.penumbra_m:.1f}" if m.penumbra_m is not None else "-"
            print(f"| {frame} | {distance:.3f} | {name} | {m.contrast:.3f} | {pen} | {1e4 * m.area_m2:.1f} |",
                  flush=True)


def main() -> None:
    import sys

    if "--fig5" in sys.argv[1:]:
        fig5_shadow()
        return
    scenes = [("fig4", builtin_scene("fig4")), *[(n, HERE / f"{n}.toml") for n in ("spheres", "cylinders", "far")]]
    print("| scene | projected light field | cross error | real side: error, energy ratio, error after best scale "
          "| synthetic side: error | ground truth's noise (real) |")
    print("|---|---|---|---|---|---|")
    for name, path in scenes:
        scene = quick_scene(load_scene(path))
        for variant in ("box", "true geometry", "measured depth"):
            opened = open_rig(scene, RunOptions(truth_seed=2))
            known = knowledge(opened, scene, "oracle")
            settings = replace(transfer_settings(scene), bounces=2, reconstruction="linear")
            if variant == "box":
                landing = None
            elif variant == "true geometry":
                landing = true_landing(opened)
            else:
                side = SyntheticSide(known.model, known.scene, settings)
                U = settings.angular_samples
                landing = depth_landing(measured_depth(opened, side), LightField.zeros(known.model.array, U, U).mask())
            opened.start_frame(0)
            if landing is None:
                result = run_transfer(opened.rig, known.model, known.scene, settings)
            else:
                with projecting(landing):
                    result = run_transfer(opened.rig, known.model, known.scene, settings)
            m = evaluate(result, render_ground_truth(opened.world, spp=GT_SPP))
            real, syn = m.cross_by_side["real"], m.cross_by_side["synthetic"]
            print(f"| {name} | {variant} | {m.cross_transfer_rel_error:.3f} "
                  f"| {real.rel_error:.3f}, {real.energy_ratio:.3f}, {real.rel_error_shape:.3f} "
                  f"| {syn.rel_error:.3f} | {real.gt_noise_rel:.3f} |", flush=True)


if __name__ == "__main__":
    main()

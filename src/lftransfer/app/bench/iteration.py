"""The speed benchmark: one light field transfer iteration, its stages, the peer, and fast-vs-exact accuracy.

A pipeline iteration is what a live system does per frame once the rig has captured: decode the LF camera
image, relight the synthetic scene with the decoded light field (and the virtual point light), render the
synthetic light field, encode it for the projector, render the view and composite it over the real view. The
rig's capture is physics in a real rig: it is timed on its own (``capture_ms``), not as part of the iteration.

The peer does the light field part of the same job with Mitsuba's own plugins (built-in ``path`` integrator,
one ``projector`` emitter per lenslet, i.e. the paper's point model), at the sample count that reaches the same
RMSE against the converged point-model light field as our fast point-model path.
"""

from __future__ import annotations

import resource
import statistics
import time
from dataclasses import dataclass
from typing import Callable

import numpy as np

from lftransfer.backend import mitsuba, variant
from lftransfer.composite import composite
from lftransfer.render.camera import sensor_dict
from lftransfer.render.fast import CachedRenderer
from lftransfer.render.lights import LightFieldLight, PointLight
from lftransfer.render.renderer import HalfSpaceRenderer
from lftransfer.rig.model import nominal_rig
from lftransfer.sim.rig import SimRig
from lftransfer.sim.verify import psnr

Progress = Callable[[str], None]
STAGES = ("decode", "relight", "render_lightfield", "encode", "render_view", "composite")


@dataclass(frozen=True)
class BenchSettings:
    """What the benchmark runs.

    Attributes:
        iterations: timed pipeline iterations (after one warm-up).
        lighting_model: lighting model of the fast path.
        view_spp: rays per view pixel in the iteration.
        lf_spp: rays per light field sample in the iteration.
        exact_aperture_samples: aperture points per lenslet of the exact reference path.
        cache_edge: longest triangle edge of the fast path's irradiance cache, metres.
        peer: run the Mitsuba peer.
        peer_max_spp: largest peer sample count tried.
    """

    iterations: int = 10
    lighting_model: str = "area"
    view_spp: int = 1
    lf_spp: int = 1
    exact_aperture_samples: int = 32
    cache_edge: float = 0.006
    peer: bool = True
    peer_max_spp: int = 4096


def _ms(seconds: list[float]) -> dict:
    ms = [1000.0 * s for s in seconds]
    return {"median": round(statistics.median(ms), 2), "min": round(min(ms), 2), "max": round(max(ms), 2),
            "stdev": round(statistics.pstdev(ms), 2)}


def run_bench(scene, settings: BenchSettings = BenchSettings(), *, progress: Progress | None = None) -> dict:
    """Measure the pipeline iteration, its stages, the rig's capture, the peer and fast-vs-exact accuracy.

    Args:
        scene: ``lftransfer.scenes.SceneConfig`` (diffuse synthetic objects, for the fast path).
        settings: see :class:`BenchSettings`.
        progress: called with a short description before each step.

    Returns:
        dict with pipeline_iteration_ms, stages_ms, capture_ms, peer_ratio, peer_spp, fast_vs_exact_psnr_db,
        variant, peak_rss_mb, resolution and details.
    """
    import drjit as dr

    mi = mitsuba()
    step = progress or (lambda _m: None)
    U = V = scene.rig.angular_samples
    model = nominal_rig(scene.rig)
    step("set up the simulated rig and the codecs")
    rig = SimRig(scene)
    decoder, encoder = model.decoder(U, V), model.encoder(U, V)
    view = scene.view
    width, height = view.resolution
    sensor = mi.load_dict(sensor_dict(view.origin, view.target, view.up, view.fov_deg, width, height))
    point_light = PointLight(np.asarray(scene.light.position, float), np.asarray(scene.light.intensity, float))
    fast = CachedRenderer(scene.synthetic, max_edge=settings.cache_edge)

    # Inputs of a live frame: the rig captures while showing the synthetic light field of the last frame.
    step("capture (the rig's physics, timed on its own)")
    rig.project(rig.info.black())
    t = time.perf_counter()
    rig.capture_lf()
    capture_s = [time.perf_counter() - t]
    real_view = rig.capture_view().radiance
    ls0 = fast.render_lightfield(model.array, [point_light], U, V, model="point", spp=1)
    rig.project(encoder(ls0))
    t = time.perf_counter()
    raw = rig.capture_lf().codes
    capture_s.append(time.perf_counter() - t)

    def iteration(timings: dict[str, list[float]] | None):
        marks = [time.perf_counter()]

        def mark(stage):
            dr.sync_thread()
            marks.append(time.perf_counter())
            if timings is not None:
                timings[stage].append(marks[-1] - marks[-2])

        captured = decoder(raw)
        mark("decode")
        lights = [point_light, LightFieldLight(captured, side="synthetic", model=settings.lighting_model,
                                               aperture_samples=scene.render.aperture_samples)]
        fast.relight(lights)
        mark("relight")
        ls = fast.render_lightfield(model.array, lights, U, V, model="area" if settings.lighting_model == "area"
                                    else "point", spp=settings.lf_spp)
        mark("render_lightfield")
        pattern = encoder(ls)
        mark("encode")
        s = fast.render_view(sensor, width, height, lights, spp=settings.view_spp)
        mark("render_view")
        frame = composite(s.rgb, s.alpha, real_view)
        mark("composite")
        return pattern, frame

    step("warm-up iteration (JIT compilation, caches)")
    iteration(None)
    timings: dict[str, list[float]] = {k: [] for k in STAGES}
    totals = []
    for i in range(settings.iterations):
        step(f"pipeline iteration {i + 1}/{settings.iterations}")
        t = time.perf_counter()
        iteration(timings)
        totals.append(time.perf_counter() - t)

    result = {
        "pipeline_iteration_ms": round(1000 * statistics.median(totals), 2),
        "pipeline_iteration_spread_ms": _ms(totals),
        "stages_ms": {k: _ms(v) for k, v in timings.items()},
        "capture_ms": round(1000 * statistics.median(capture_s), 1),
        "iterations": settings.iterations,
        "lighting_model": settings.lighting_model,
        "cache_vertices": fast.cache_size,
    }

    # Accuracy: fast path against the exact reference path (area model, densely sampled, shadow rays).
    step("fast vs exact: exact reference render (dense aperture sampling)")
    captured = decoder(raw)
    exact = HalfSpaceRenderer(scene.synthetic, max_depth=scene.render.max_depth)
    spp = max(4, settings.view_spp)
    ref_lights = [point_light, LightFieldLight(captured, side="synthetic", model="area",
                                               aperture_samples=settings.exact_aperture_samples)]
    s_exact = exact.render_view(sensor, width, height, ref_lights, spp=spp)
    fast_lights = [point_light, LightFieldLight(captured, side="synthetic", model=settings.lighting_model,
                                                aperture_samples=scene.render.aperture_samples)]
    s_fast = fast.render_view(sensor, width, height, fast_lights, spp=spp)
    ref = composite(s_exact.rgb, s_exact.alpha, real_view)
    result["fast_vs_exact_psnr_db"] = round(psnr(composite(s_fast.rgb, s_fast.alpha, real_view), ref), 2)

    if settings.peer:
        result.update(_peer(scene, model, fast, captured, U, V, settings, step))
    result.update({
        "variant": variant(),
        "peak_rss_mb": round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0, 1),
        "resolution": {"lenslets": [scene.rig.rows, scene.rig.cols], "lattice": scene.rig.lattice,
                       "lf_camera": list(scene.rig.lf_camera), "projector": list(scene.rig.projector),
                       "view": list(view.resolution), "angular_samples": U, "view_spp": settings.view_spp,
                       "lf_spp": settings.lf_spp},
    })
    return result


def _peer(scene, model, fast: CachedRenderer, captured, U: int, V: int, settings: BenchSettings, step) -> dict:
    """Time Mitsuba's path integrator on the light field part of the job, at equal RMSE (point model)."""
    import drjit as dr

    from lftransfer.app.bench.peer import PeerRenderer, rmse, spp_for_rmse

    step("peer: converged point-model light field (exact path, averaged over each sample's footprint)")
    light = LightFieldLight(captured, side="synthetic", model="point")
    exact = HalfSpaceRenderer(scene.synthetic, max_depth=1)
    reference = footprint_average(exact, model.array, [light], U, V)
    # Ours, same job: relight with the point model and render the light field through pinholes.
    times = []
    for _ in range(max(3, settings.iterations // 2)):
        t = time.perf_counter()
        fast.relight([light])
        ours = fast.render_lightfield(model.array, [light], U, V, model="point", spp=1)
        dr.sync_thread()
        times.append(time.perf_counter() - t)
    ours_s = statistics.median(times)
    target = rmse(ours, reference)
    step(f"peer: Mitsuba path + {model.array.K} projector emitters, searching spp for RMSE {target:.3g}")
    peer = PeerRenderer(scene.synthetic, captured, U, V, max_depth=1)
    spp, peer_s, peer_rmse = spp_for_rmse(peer, reference, target, max_spp=settings.peer_max_spp)
    return {
        "peer_ratio": round(peer_s / ours_s, 1),
        "peer_spp": spp,
        "peer_ms": round(1000 * peer_s, 1),
        "peer_rmse": peer_rmse,
        "ours_lightfield_ms": round(1000 * ours_s, 2),
        "ours_rmse": target,
        "peer_reached_target": bool(peer_rmse <= target),
    }


def footprint_average(renderer: HalfSpaceRenderer, array, lights, U: int, V: int, n: int = 4):
    """Light field of pinhole lenslet cameras averaged over each sample's (u, v) footprint (n x n sub-samples).

    This is what a light field render converges to when its rays are spread over the sample's cell, as a
    ``batch`` sensor's pixels are: the common reference of our path and the peer.

    Returns:
        LightField (K, V, U, 3), masked samples zero.
    """
    from lftransfer.lightfield import LightField

    lf = LightField.zeros(array, U, V)
    a = array.half_width
    step_u, step_v = 2 * a / U, 2 * a / V
    sub = (np.arange(n) + 0.5) / n - 0.5
    uu = lf.u[None, :, None, None] + step_u * sub[None, None, None, :]     # (1, U, 1, n)
    vv = lf.v[:, None, None, None] + step_v * sub[None, None, :, None]     # (V, 1, n, 1)
    uu, vv = np.broadcast_arrays(uu, vv)                                     # (V, U, n, n)
    d = -np.stack([uu, vv, np.ones_like(uu)], -1)
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    K = array.K
    origins = np.zeros((K, V * U * n * n, 3), np.float32)
    origins[..., :2] = array.centres[:, None, :]
    dirs = np.broadcast_to(d.reshape(1, -1, 3), origins.shape)
    radiance, _, _ = renderer.render_rays(origins.reshape(-1, 3), dirs.reshape(-1, 3), lights)
    lf.data[...] = radiance.reshape(K, V, U, n * n, 3).mean(axis=3) * lf.mask()[None, :, :, None]
    return lf

"""Accuracy and speed of the fast path's glossy lobes against the exact path (not a test: a measurement).

    .venv/bin/python tests/render/measure_glossy.py [--quick] [--timing]

Accuracy, on the scene of tests/render/test_fast.py (a 50 mm cube and a 15 mm ball under a 3 x 4 hexagonal
array of 25.4 mm lenslets, lit by a smooth direction-dependent light field, area model, and a point light): the
view image (96 x 72, 4 rays per pixel) of the fast path and of the exact path (``HalfSpaceRenderer``,
``max_depth=1``, 4 aperture points: its default) against a converged exact path (256 aperture points) on the
same rays, over the pixels fully covered by the objects: PSNR (peak: the reference's maximum) and the relative
L1 error sum|x - ref| / sum|ref|. ``--timing``: one frame of the Fig. 4 scene at quarter resolution (light field
out, 16 x 16 x 4 rays per lenslet, and view, 256 x 192 x 4 rays), relit for a new captured light field as the
live loop does, fast against exact, median of 5 frames.
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

from lftransfer.backend import mitsuba
from lftransfer.lightfield import LightField
from lftransfer.optics import LensArray
from lftransfer.render.camera import sensor_dict
from lftransfer.render.fast import CachedRenderer
from lftransfer.render.lights import LightFieldLight, PointLight
from lftransfer.render.renderer import HalfSpaceRenderer
from lftransfer.scenes.format import ObjectConfig

ARRAY = LensArray(lattice="hex", rows=3, cols=4, pitch=0.0254, focal_length=0.0254)
W, H, SPP = 96, 72, 4


def objects(material: dict) -> list[ObjectConfig]:
    """The cube and the ball of tests/render/test_fast.py, both of ``material``."""
    return [ObjectConfig.model_validate({"name": "cube", "shape": "box", "size": [0.05] * 3,
                                         "translate": [0.0, 0.0, -0.08], "rotate_deg": [0, 30, 0],
                                         "material": material}),
            ObjectConfig.model_validate({"name": "ball", "shape": "sphere", "radius": 0.015,
                                         "translate": [0.05, 0.02, -0.06], "material": material})]


def incident() -> LightField:
    """The smooth, direction-dependent captured light field of tests/render/test_fast.py."""
    lf = LightField.zeros(ARRAY, 12, 12)
    uu, vv = np.meshgrid(lf.u, lf.v)
    k = np.arange(ARRAY.K)[:, None, None]
    lf.data[..., 0] = 1.0 + 0.5 * uu + 0.1 * k / ARRAY.K
    lf.data[..., 1] = 0.8 - 0.4 * vv
    lf.data[..., 2] = 0.5 + 0.3 * uu * vv
    lf.data *= lf.mask()[None, :, :, None]
    return lf


def errors(image: np.ndarray, reference: np.ndarray, mask: np.ndarray) -> tuple[float, float]:
    """(PSNR dB over ``mask``, relative L1 error over ``mask``) of (H, W, 3) images; nan where the reference is
    black there."""
    if not np.abs(reference[mask]).sum() > 0:
        return float("nan"), float("nan")
    err = image[mask].astype(np.float64) - reference[mask]
    return (float(10 * np.log10(reference.max() ** 2 / np.mean(err ** 2))),
            float(np.abs(err).sum() / np.abs(reference[mask]).sum()))


def accuracy(material: dict, light: str = "field", reconstruction: str = "box", reference_samples: int = 256,
             seed: int = 3) -> dict:
    """Fast, exact (default samples) and the diffuse cache alone against the converged exact path, for one
    material lit by the light field (``light="field"``) or the point light (``"point"``)."""
    mi = mitsuba()
    sensor = mi.load_dict(sensor_dict([0.3, 0.1, 0.0], [0.0, 0.0, -0.07], [0, 1, 0], 30.0, W, H))
    point = PointLight(np.array([0.2, 0.15, 0.0]), np.array([1.0, 0.8, 0.6]))

    def lights(m: int, light_seed: int):
        if light == "point":
            return [point]
        return [LightFieldLight(incident(), "synthetic", model="area", aperture_samples=m, seed=light_seed,
                                reconstruction=reconstruction)]

    exact = HalfSpaceRenderer(objects(material), max_depth=1)
    reference = exact.render_view(sensor, W, H, lights(reference_samples, 9), spp=SPP, seed=seed)
    plain = exact.render_view(sensor, W, H, lights(4, 0), spp=SPP, seed=seed)
    fast = CachedRenderer(objects(material)).render_view(sensor, W, H, lights(4, 0), spp=SPP, seed=seed)
    control = CachedRenderer(objects(material), glossy=False).render_view(sensor, W, H, lights(4, 0), spp=SPP,
                                                                          seed=seed)
    mask = reference.alpha >= 1.0
    return {"fast": errors(fast.rgb, reference.rgb, mask), "exact": errors(plain.rgb, reference.rgb, mask),
            "diffuse_only": errors(control.rgb, reference.rgb, mask)}


def timing(material: dict, frames: int = 5, quick: bool = True) -> dict:
    """Median seconds of one live frame (relight for a new light field, light field out, view) on the Fig. 4
    scene at quarter (``quick``) or full resolution with its synthetic cube made of ``material``, fast and
    exact."""
    from lftransfer.scenes import quick_scene
    from lftransfer.rig.model import nominal_rig
    from lftransfer.scenes import builtin_scene, load_scene, with_overrides

    mi = mitsuba()
    scene = load_scene(builtin_scene("fig4"))
    scene = quick_scene(scene) if quick else scene
    array = nominal_rig(scene.rig).array
    U = scene.rig.angular_samples
    w, h = scene.view.resolution
    sensor = mi.load_dict(sensor_dict(scene.view.origin, scene.view.target, scene.view.up, scene.view.fov_deg, w, h))
    point = PointLight(np.array(scene.lights[0].position), np.array(scene.lights[0].intensity))
    captured = HalfSpaceRenderer(scene.real, max_depth=1).render_lightfield(array, [point], U, U, side="real",
                                                                           model="area", spp=4)
    synthetic = with_overrides(scene, synthetic=[{**scene.synthetic[0].model_dump(mode="json"),
                                                  "material": material}]).synthetic
    out = {}
    for name, renderer in (("fast", CachedRenderer(synthetic)), ("exact", HalfSpaceRenderer(synthetic, max_depth=1))):
        times = []
        for _ in range(frames + 1):
            # as the live loop: a new captured light field every frame, the same seed
            lights = [point, LightFieldLight(captured.copy(), "synthetic", model="area", aperture_samples=4,
                                             reconstruction="linear")]
            t0 = time.perf_counter()
            renderer.render_lightfield(array, lights, U, U, model="area", spp=4)
            renderer.render_view(sensor, w, h, lights, spp=4)
            times.append(time.perf_counter() - t0)
        out[name] = statistics.median(times[1:])       # the first frame compiles the kernels
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true", help="roughness 0.05, 0.1, 0.3 only")
    parser.add_argument("--timing", action="store_true", help="also time the Fig. 4 scene, quarter resolution")
    parser.add_argument("--full", action="store_true", help="time at full resolution instead (slow)")
    args = parser.parse_args()
    roughness = (0.05, 0.1, 0.3) if args.quick else (0.0, 0.02, 0.05, 0.1, 0.2, 0.3, 0.5, 0.8)
    materials = [("diffuse", {"type": "diffuse", "albedo": [0.3, 0.8, 0.4]})]
    for r in roughness:
        materials.append((f"glossy {r:.2f}", {"type": "glossy", "albedo": [0.3, 0.8, 0.4], "roughness": r}))
    for r in roughness:
        materials.append((f"metal {r:.2f}", {"type": "metal", "specular": [0.9, 0.7, 0.5], "roughness": r}))
    print("PSNR dB / relative error against the converged exact path; light field (area model), then point light")
    print("material      | LF: fast        exact(M=4)    diffuse only | point: fast     diffuse only"
          + (" | frame fast, exact, speed-up" if args.timing else ""))

    def pair(e):
        return f"{e[0]:5.1f} {e[1]:6.3f}" if np.isfinite(e[1]) else "  (exact: 0)"

    for name, material in materials:
        a, p = accuracy(material, "field"), accuracy(material, "point")
        line = (f"{name:13s} | {pair(a['fast'])}  {pair(a['exact'])}  {pair(a['diffuse_only'])} | "
                f"{pair(p['fast'])}  {pair(p['diffuse_only'])}")
        if args.timing:
            t = timing(material, frames=4 if args.full else 7, quick=not args.full)
            line += f" | {t['fast'] * 1000:6.0f} ms {t['exact'] * 1000:6.0f} ms x{t['exact'] / t['fast']:.1f}"
        print(line, flush=True)


if __name__ == "__main__":
    main()

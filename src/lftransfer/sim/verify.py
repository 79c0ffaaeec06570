"""Verification against path-traced ground truth (DESIGN.md section 6). Only this module (and tests) may read
a simulated rig's hidden truth.

The ground truth is the union scene (real objects + synthetic objects + point light, no lens array) path traced
from the view camera with Mitsuba's ``path`` integrator; the real-alone and synthetic-alone scenes are rendered
with the same seeds so that their noise cancels in the cross-transfer term. Two independent seeds give the
ground truth's own noise. Renders are cached under a hash of everything they depend on.
"""

from __future__ import annotations

import hashlib
import json
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from lftransfer.composite import composite
from lftransfer.imageio_utils import read_exr, write_exr
from lftransfer.optics.geometry import apply_homography, rotation_xy, rotation_z
from lftransfer.render.camera import sensor_dict
from lftransfer.render.shapes import scene_dict

GT_MAX_DEPTH = 12  # Mitsuba path depth (counts the segment to the emitter): far beyond what transfer keeps


@dataclass
class GroundTruth:
    """Ground-truth view images, each rendered with two independent seeds.

    Attributes:
        union: (2, H, W, 3) float32, all objects together.
        real: (2, H, W, 3) float32, real objects alone.
        synthetic: (2, H, W, 3) float32, synthetic objects alone.
        alpha_real, alpha_synthetic: (H, W) float32 coverage of each set of objects.
    """

    union: np.ndarray
    real: np.ndarray
    synthetic: np.ndarray
    alpha_real: np.ndarray
    alpha_synthetic: np.ndarray

    @property
    def image(self) -> np.ndarray:
        """(H, W, 3) the ground truth: the mean of the two union renders."""
        return self.union.mean(axis=0)


def cache_dir() -> Path:
    """Folder of cached ground-truth renders: ``$LFT_CACHE_DIR`` or ``~/.cache/lftransfer``."""
    return Path(os.environ.get("LFT_CACHE_DIR", Path.home() / ".cache" / "lftransfer")) / "ground_truth"


def _key(scene, spp: int, seeds: tuple[int, ...]) -> str:
    import mitsuba

    def objects(objs):
        out = []
        for o in objs:
            d = o.model_dump(mode="json")
            if getattr(o, "file", None):
                d["file_sha"] = hashlib.sha256(Path(o.file).read_bytes()).hexdigest()
            out.append(d)
        return out

    payload = {
        "real": objects(scene.real), "synthetic": objects(scene.synthetic),
        "light": scene.light.model_dump(mode="json"), "view": scene.view.model_dump(mode="json"),
        "spp": spp, "seeds": list(seeds), "depth": GT_MAX_DEPTH, "mitsuba": mitsuba.__version__, "v": 1,
    }
    return hashlib.sha256(json.dumps(payload, sort_keys=True).encode()).hexdigest()[:20]


def render_ground_truth(scene, *, spp: int = 256, seeds: tuple[int, int] = (1, 2), use_cache: bool = True,
                        progress: Callable[[str], None] | None = None) -> GroundTruth:
    """Path trace the union, real-alone and synthetic-alone scenes from the view camera.

    Args:
        scene: ``lftransfer.scenes.SceneConfig`` (its ``real`` objects are the hidden truth).
        spp: samples per pixel of each render.
        seeds: the two independent seeds.
        use_cache: read and write the cache (:func:`cache_dir`).
        progress: called before each render.

    Returns:
        GroundTruth.
    """
    from lftransfer.backend import mitsuba

    key = _key(scene, spp, seeds)
    path = cache_dir() / f"{key}.exr"
    if use_cache and path.exists():
        stack = read_exr(path)                                           # (H, W, 3*3*2 + 2)
        return _unpack(stack)
    mi = mitsuba()
    view = scene.view
    w, h = view.resolution
    light = {"type": "point", "position": list(map(float, scene.light.position)),
             "intensity": {"type": "rgb", "value": list(map(float, scene.light.intensity))}}
    extra = {"sensor": sensor_dict(view.origin, view.target, view.up, view.fov_deg, w, h, spp=spp),
             "integrator": {"type": "path", "max_depth": GT_MAX_DEPTH, "hide_emitters": True},
             "point_light": light}
    images: dict[str, list[np.ndarray]] = {}
    for name, objs in (("union", scene.real + scene.synthetic), ("real", scene.real), ("synthetic", scene.synthetic)):
        mscene = mi.load_dict(scene_dict(objs, extra=extra), parallel=False, optimize=False)
        images[name] = []
        for seed in seeds:
            if progress:
                progress(f"ground truth: {name}, seed {seed}")
            images[name].append(np.array(mi.render(mscene, spp=spp, seed=seed), dtype=np.float32))
    stack = np.concatenate([images[n][i][..., :3] for n in ("union", "real", "synthetic") for i in range(2)]
                           + [images["real"][0][..., 3:4], images["synthetic"][0][..., 3:4]], axis=-1)
    if use_cache:
        write_exr(path, stack)
    return _unpack(stack)


def _unpack(stack: np.ndarray) -> GroundTruth:
    parts = [stack[..., 3 * i:3 * i + 3] for i in range(6)]
    return GroundTruth(union=np.stack(parts[0:2]), real=np.stack(parts[2:4]), synthetic=np.stack(parts[4:6]),
                       alpha_real=stack[..., 18], alpha_synthetic=stack[..., 19])


def downsample(image: np.ndarray, factor: int) -> np.ndarray:
    """Box-downsample the first two axes by an integer factor (cropping the remainder)."""
    if factor <= 1:
        return np.asarray(image, np.float64)
    h, w = image.shape[0] // factor * factor, image.shape[1] // factor * factor
    x = np.asarray(image[:h, :w], np.float64)
    return x.reshape(h // factor, factor, w // factor, factor, *x.shape[2:]).mean(axis=(1, 3))


def psnr(image: np.ndarray, reference: np.ndarray, peak: float | None = None) -> float:
    """Peak signal-to-noise ratio in dB; ``peak`` defaults to the reference's maximum."""
    peak = float(np.max(reference)) if peak is None else peak
    mse = float(np.mean((np.asarray(image, np.float64) - reference) ** 2))
    return float("inf") if mse == 0 else 10.0 * np.log10(peak * peak / mse)


def metric_factor(width: int, target_width: int = 256) -> int:
    """Integer box-downsampling factor that brings ``width`` to about ``target_width``."""
    return max(1, int(round(width / target_width)))


def evaluate(result, gt: GroundTruth, *, target_width: int = 256) -> dict:
    """Metrics of a transfer result against the ground truth (DESIGN.md section 6).

    Args:
        result: ``lftransfer.transfer.TransferResult``.
        gt: :class:`GroundTruth` at the same view resolution.
        target_width: metrics are computed on images box-downsampled to about this width.

    Returns:
        dict with psnr_db, psnr_db_direct_only, cross_transfer_rel_error, gt_noise_psnr_db, cross_gt_noise_rel,
        metric_resolution and the energies of the cross terms.
    """
    f = metric_factor(result.real_view.shape[1], target_width)
    alpha = result.synthetic_view.alpha
    comp_n = composite(result.synthetic_view.rgb, alpha, result.real_view)
    s0 = result.bounces[0].synthetic_view
    comp_0 = composite(s0.rgb, alpha, result.real_view_direct)
    ds = lambda x: downsample(x, f)  # noqa: E731
    union = ds(gt.image)
    peak = float(union.max())
    # Cross-transfer terms: what the objects add to each other's appearance.
    c_gt_pair = [ds(gt.union[i] - composite(gt.synthetic[i], gt.alpha_synthetic, gt.real[i])) for i in range(2)]
    c_gt = 0.5 * (c_gt_pair[0] + c_gt_pair[1])
    c_lft = ds(comp_n - comp_0)
    mask = (ds(gt.alpha_real) > 0) | (ds(gt.alpha_synthetic) > 0)
    norm = lambda x: float(np.sqrt(np.sum(x[mask] ** 2)))  # noqa: E731
    c_norm = norm(c_gt)
    return {
        "psnr_db": psnr(ds(comp_n), union, peak),
        "psnr_db_direct_only": psnr(ds(comp_0), union, peak),
        "cross_transfer_rel_error": norm(c_lft - c_gt) / c_norm if c_norm > 0 else float("nan"),
        "gt_noise_psnr_db": psnr(ds(gt.union[0]), ds(gt.union[1]), peak),
        "cross_gt_noise_rel": norm(c_gt_pair[0] - c_gt_pair[1]) / c_norm if c_norm > 0 else float("nan"),
        "cross_term_rel_size": c_norm / float(np.sqrt(np.sum(union[mask] ** 2))),
        "metric_resolution": [int(union.shape[1]), int(union.shape[0])],
        "metric_pixels": int(mask.sum()),
    }


# ---- calibration against the hidden truth -----------------------------------------------------------------------

def _rig_rotation(model) -> np.ndarray:
    return rotation_xy(model.tilt) @ rotation_z(model.array.rotation)


def calibration_errors(calibration, truth, *, max_pixels: int = 200_000) -> dict:
    """Errors of a calibration against the simulated rig's hidden truth (verification only).

    Args:
        calibration: :class:`lftransfer.calibration.rig.Calibration`.
        truth: the true ``RigModel`` (``SimRig.truth``).
        max_pixels: camera pixels sampled for the ray and mapping errors.

    Returns:
        JSON-ready dict: lenslet centres (LF camera px), projector mapping (projector px), global pose (mm,
        degrees), pitch, ray directions (degrees), responses (fraction of full scale), cross-talk, black level,
        brightness, exposure, vignetting.
    """
    from lftransfer.calibration.radiometric import response_error

    cal = calibration.model
    out: dict = {}
    ta, ca = truth.array, cal.array
    tcam, ccam = truth.camera, cal.camera
    if calibration.lattice is not None:
        lat = calibration.lattice
        k = lat.indices[:, 0] * ta.cols + lat.indices[:, 1]
        true_px = tcam.device.ray_to_pixel(ta, k, np.tile([0.0, 0.0, 1.0], (len(k), 1)))
        err = np.linalg.norm(lat.centres - true_px, axis=1)
        out["lenslet_centre_rms_px"] = float(np.sqrt(np.mean(err ** 2)))
        out["lenslet_centre_max_px"] = float(err.max())
        out["lenslets_found"] = int(len(k))
    # camera pixels behind lenslets, a sample
    h, w = tcam.device.height, tcam.device.width
    rng = np.random.default_rng(0)
    px = np.stack([rng.uniform(0, w - 1, max_pixels), rng.uniform(0, h - 1, max_pixels)], 1)
    kt, dt = tcam.device.pixel_to_ray(ta, px)
    kc, dc = ccam.device.pixel_to_ray(ca, px)
    both = (kt >= 0) & (kc >= 0)
    same = both & (kt == kc)
    out["lenslet_assignment_agreement"] = float(same.sum() / max(both.sum(), 1))
    rt, rc = _rig_rotation(truth), _rig_rotation(cal)
    dw_t, dw_c = dt[same] @ rt.T, dc[same] @ rc.T                       # world directions
    ang = np.degrees(np.arccos(np.clip(np.sum(dw_t * dw_c, axis=1), -1, 1)))
    out["ray_direction_rms_deg"] = float(np.sqrt(np.mean(ang ** 2)))

    def to_prj(model, p):
        return apply_homography(model.projector.device.homography @ np.linalg.inv(model.camera.device.homography), p)

    inside = kt >= 0
    e = np.linalg.norm(to_prj(cal, px[inside]) - to_prj(truth, px[inside]), axis=1)
    out["projector_mapping_rms_px"] = float(np.sqrt(np.mean(e ** 2)))
    # global pose: the lenslet centres in the world, and the array's orientation
    ct, cc = ta.centres3d @ rt.T, ca.centres3d @ rc.T
    d = np.linalg.norm(ct - cc, axis=1) * 1000
    out["pose_position_rms_mm"] = float(np.sqrt(np.mean(d ** 2)))
    out["pose_position_max_mm"] = float(d.max())
    cosang = (np.trace(rc.T @ rt) - 1) / 2
    out["pose_rotation_deg"] = float(np.degrees(np.arccos(np.clip(cosang, -1, 1))))
    out["pitch_rel_error"] = float(ca.pitch / ta.pitch - 1)
    kd = np.asarray(ccam.device.distortion) - np.asarray(tcam.device.distortion)
    out["distortion_k1_rms"] = float(np.sqrt(np.mean(kd[:, 0] ** 2)))
    # radiometry
    out["camera_response_error"] = response_error(ccam.response, tcam.response)
    out["projector_response_error"] = response_error(cal.projector.response, truth.projector.response)
    tp, cp = truth.projector, cal.projector

    mt, mc = tp.max_radiance * tp.cross_talk_matrix, cp.max_radiance * cp.cross_talk_matrix
    out["projector_mixing_rel_error"] = float(np.abs(mc - mt).max() / np.abs(mt).max())
    bt = tp.max_radiance * np.asarray(tp.black_level)
    bc = cp.max_radiance * np.asarray(cp.black_level)
    out["black_level_error"] = float(np.abs(bc - bt).max() / tp.max_radiance)
    out["exposure_rel_error"] = float(ccam.exposure / tcam.exposure - 1)
    if tcam.vignetting is not None and ccam.vignetting is not None:
        ys, xs = px[inside, 1].astype(int), px[inside, 0].astype(int)
        st = tcam.exposure * tcam.vignetting[ys, xs]
        sc = ccam.exposure * ccam.vignetting[ys, xs]
        out["camera_gain_rel_rms"] = float(np.sqrt(np.mean((sc / st - 1) ** 2)))
    return out

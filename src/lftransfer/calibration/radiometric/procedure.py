"""The procedure of :mod:`lftransfer.calibration.radiometric`: :func:`calibrate_radiometry` runs steps (a) to (d) and
gathers the diagnostics."""

from __future__ import annotations

import time

import numpy as np

from lftransfer.calibration.radiometric.brightness import _BoardMeasurement, _measure_brightness
from lftransfer.calibration.radiometric.camera_response import _CameraResponse, _measure_camera_response
from lftransfer.calibration.radiometric.common import Progress
from lftransfer.calibration.radiometric.focal_plane import _FocalPlane
from lftransfer.calibration.radiometric.projector import _ProjectorFit, _measure_projector
from lftransfer.calibration.radiometric.result import Radiometry
from lftransfer.calibration.radiometric.vignetting import _FlatField, _measure_vignetting
from lftransfer.rig.base import Rig


def _diagnostics(response: _CameraResponse, flat: _FlatField, projector_fit: _ProjectorFit,
                 board: _BoardMeasurement, focal_plane_captures: int, timings: dict[str, float]) -> dict:
    """The measurements behind the result, JSON-ready (see :func:`calibrate_radiometry`)."""
    cx, cy = board.centre_pixel
    return {
        "camera_response_samples": response.diag["samples"],
        "camera_response_pixels": response.diag["pixels"],
        "exposure_scales": response.scales.tolist(),
        "flat_exposure_scale": flat.exposure,
        "black_exposure_scale": projector_fit.black_exposure,
        "vignetting_fit": flat.diag,
        "projector_levels": projector_fit.levels.tolist(),
        "projector_response_samples": projector_fit.response_samples,
        "projector_fit_rms": projector_fit.fit_rms,
        "black_signal": projector_fit.black.tolist(),
        "channel_signals": projector_fit.samples.tolist(),
        "board_pixels": board.pixels,
        "board_centre_m": board.held[:3, 3].tolist(),
        "board_centre_pixel": [int(cx), int(cy)],
        "board_translucent": board.translucent,
        "board_ratio_per_channel": board.per_channel.tolist(),
        "board_measured_mean": board.measured_mean.tolist(),
        # focal-plane signal per unit exposure_scale and radiance = diffuser transmission x camera exposure
        "exposure_times_diffuser": projector_fit.scale / board.max_radiance,
        "camera_exposure_source": "model (no capture measures it)",
        "captures": {"focal_plane": focal_plane_captures, "board": 2 if board.translucent else 1},
        "timings_s": {k: round(v, 3) for k, v in timings.items()},
    }


def calibrate_radiometry(rig: Rig, model, scene, *, progress: Progress | None = None,
                         exposures: int = 5, projector_levels: int = 4, vignetting_degree: int = 4,
                         board_spp: int | None = None, predict_spp: int = 16, angular_samples: int = 64,
                         seed: int = 0, walls=None) -> Radiometry:
    """Calibrate the camera's and the projector's radiometry from rig captures (module docstring: the steps).

    Args:
        rig: the rig; it is asked for the focal-plane diffuser (with exposure bracketing) and a grey board.
        model: the current ``RigModel`` (calibrated geometry; its bit depths and exposure are used).
        scene: the scene (``SceneConfig``): nominal rig file values and the view camera.
        progress: called with a message once per capture group.
        exposures: captures of the exposure bracket of step (a) (factors of 2 apart).
        projector_levels: uniform levels per projector channel in step (c).
        vignetting_degree: total degree of the vignetting polynomial.
        board_spp: view camera samples per pixel of the board capture (None: the rig's default).
        predict_spp: samples per pixel of our own render of the board.
        angular_samples: U = V of the light field that lights our own render of the board.
        seed: seed of the sampling in our own render and of the diagnostic subsets.
        walls: the other light field interfaces' planes in this array's frame, which the board keeps clear of
            (:func:`lftransfer.calibration.pose.board_pattern`), or None.

    Returns:
        Radiometry. ``diagnostics`` holds the camera response samples (per channel a list of (relative
        exposure x linear signal, normalised code)), the projector response samples (per channel a list of
        (normalised code, measured normalised drive)), fit residuals, the exposure scales used, the board
        measurement, ``exposure_times_diffuser`` and timings.
    """
    say = progress or (lambda message: None)
    rng = np.random.default_rng(seed)
    t_start = time.perf_counter()
    timings: dict[str, float] = {}
    fp = _FocalPlane(rig, tuple(rig.info.projector_shape), model.projector.levels, model.projector.dtype,
                     float(model.camera.levels))

    t = time.perf_counter()
    response = _measure_camera_response(fp, model, exposures, rng, say)                           # a.
    timings["camera_response"] = time.perf_counter() - t
    t = time.perf_counter()
    flat = _measure_vignetting(fp, response, vignetting_degree, say)                                # b.
    timings["vignetting"] = time.perf_counter() - t
    t = time.perf_counter()
    projector_fit = _measure_projector(fp, response, flat, projector_levels, say)                   # c.
    timings["projector"] = time.perf_counter() - t
    t = time.perf_counter()
    board = _measure_brightness(rig, model, scene, projector_fit, flat.white, board_spp=board_spp,   # d.
                                predict_spp=predict_spp, angular_samples=angular_samples, seed=seed, say=say,
                                walls=walls)
    timings["brightness"] = time.perf_counter() - t
    timings["total"] = time.perf_counter() - t_start

    return Radiometry(camera_gamma=response.gamma, camera_exposure=model.camera.exposure, vignetting_poly=flat.poly,
                      projector_gamma=projector_fit.gamma, cross_talk=projector_fit.cross_talk,
                      black_level=projector_fit.black_level, max_radiance=board.max_radiance,
                      diagnostics=_diagnostics(response, flat, projector_fit, board, fp.captures, timings))

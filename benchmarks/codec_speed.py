"""Speed of the device codecs at the paper's resolution (fig4 rig, U = V = 48).

Times ``decoder(raw)`` (raw uint16 -> LightField) and ``encoder(lf)`` (LightField -> uint8 projector image):
median of N runs after warm-up, plus the one-off construction time of each codec.

Usage: ``python benchmarks/codec_speed.py [--runs 30] [--build-runs 3] [--camera-gamma 2.2]``
(the machine's load shows in the timings: compare runs taken back to back).
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import statistics
import time

import cv2
import numpy as np

from lftransfer.lightfield import LightField, ResponseCurve
from lftransfer.rig.model import nominal_rig
from lftransfer.scenes import builtin_scene, load_scene


def _median_ms(fn, runs: int, warmup: int = 3) -> tuple[float, float]:
    for _ in range(warmup):
        fn()
    times = []
    for _ in range(runs):
        t0 = time.perf_counter()
        fn()
        times.append((time.perf_counter() - t0) * 1e3)
    return statistics.median(times), min(times)


def _smooth_lf(array, U: int, V: int, scale: float) -> LightField:
    """A smooth, lenslet-dependent radiance in about [0.1, 0.9] * scale, zero on masked samples."""
    lf = LightField.zeros(array, U, V)
    uu, vv = np.meshgrid(lf.u, lf.v)
    k = np.arange(array.K)[:, None, None] / array.K
    base = 0.5 + 0.15 * np.cos(3 * uu) + 0.2 * vv + 0.2 * (k - 0.5)
    data = np.stack([base, 0.8 * base + 0.1 * uu, 0.6 + 0.2 * uu * vv + 0.1 * np.sin(6.28 * k)], -1)
    lf.data[:] = np.clip(data, 0, 1) * scale * lf.mask()[None, :, :, None]
    return lf


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=30)
    ap.add_argument("--grid", type=int, default=48)
    ap.add_argument("--build-runs", type=int, default=3, help="constructions timed (the minimum is printed)")
    ap.add_argument("--camera-gamma", type=float, default=None,
                    help="override the fig4 camera gamma (1.0) to time a non-linear camera response")
    args = ap.parse_args()

    print(f"numpy {np.__version__}, OpenCV {cv2.__version__}, cv2.getNumThreads() = {cv2.getNumThreads()}, "
          f"os.cpu_count() = {os.cpu_count()}, "
          f"OMP/OPENBLAS threads = {os.environ.get('OMP_NUM_THREADS')}/{os.environ.get('OPENBLAS_NUM_THREADS')}")
    model = nominal_rig(load_scene(builtin_scene("fig4")).rig)
    if args.camera_gamma is not None:
        cam = dataclasses.replace(model.camera, response=ResponseCurve((args.camera_gamma,) * 3))
        model = dataclasses.replace(model, camera=cam)
    U = V = args.grid
    cam, prj = model.camera, model.projector
    print(f"array {model.array.lattice} {model.array.rows} x {model.array.cols} (K = {model.array.K}), "
          f"camera {cam.device.width} x {cam.device.height} {cam.bits}-bit gamma {cam.response.gamma}, "
          f"projector {prj.device.width} x {prj.device.height} {prj.bits}-bit gamma {prj.response.gamma}, "
          f"U = V = {U}")

    t_dec, t_enc = [], []
    for _ in range(args.build_runs):
        t0 = time.perf_counter()
        decoder = model.decoder(U, V)
        t_dec.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        encoder = model.encoder(U, V)
        t_enc.append(time.perf_counter() - t0)
    print(f"construction (min of {args.build_runs}): decoder {min(t_dec) * 1e3:.0f} ms, "
          f"encoder {min(t_enc) * 1e3:.0f} ms")

    # realistic inputs: a smooth light field, exposed by the camera through its own codec; the same for the projector
    lf_cam = _smooth_lf(model.array, U, V, scale=1.0 / cam.exposure * 0.9)
    raw = decoder.expose(decoder.codec.lightfield_to_image(lf_cam))
    lf_prj = _smooth_lf(model.array, U, V, scale=prj.max_radiance)
    print(f"raw {raw.shape} {raw.dtype} codes in [{raw.min()}, {raw.max()}]; "
          f"projector light field {lf_prj.data.shape} in [0, {lf_prj.data.max():.2f}]")

    med, best = _median_ms(lambda: decoder(raw), args.runs)
    print(f"decode  (raw uint16 -> LightField): median {med:7.2f} ms  (min {best:.2f}, {args.runs} runs)")
    med, best = _median_ms(lambda: encoder(lf_prj), args.runs)
    print(f"encode  (LightField -> projector) : median {med:7.2f} ms  (min {best:.2f}, {args.runs} runs)")


if __name__ == "__main__":
    main()

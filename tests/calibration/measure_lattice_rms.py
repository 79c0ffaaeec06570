"""The lattice fit's residual on good calibration images and on images that are none (not a test: a measurement).

    .venv/bin/python tests/calibration/measure_lattice_rms.py [--full] [--no-render]

It chose the limit of ``lftransfer.calibration.lenslets.procedure._refuse_poor_fit``. Each image is passed to
the lattice fit without that check (``_find_lenslet_centres_unchecked``); printed are the outcome (the fit's RMS
residual in pixels, its RMS in pitches, the detections kept against the lattice nodes they span, or the error
the fit raised before any RMS was known), per image:

* good: the simulated rig's images (the Fig. 4 scene's rig, perturbed truth, seed 1, at a quarter of its
  resolution, ``--full`` also at full resolution): the on-axis collimator (spots), the white field (white), and
  the 5 x 5 collimator tilts of the distortion sweep (tan up to 0.3, spots); the synthetic spot and white images
  of tests/calibration/test_lenslets.py (distorted, tilted, vignetted, noisy);
* bad: the LF camera's and the view camera's photographs of the Fig. 4 real scene (``--no-render`` leaves them
  out: they need Mitsuba), the scene texture ``photo.png``, and Gaussian-smoothed random textures, each read as
  spots and as white, hex and rect.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import cv2
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from lftransfer.imageio_utils import to_grey  # noqa: E402
from lftransfer.calibration.lenslets import NoSpotsError  # noqa: E402
from lftransfer.calibration.lenslets.procedure import _find_lenslet_centres_unchecked  # noqa: E402
from tests.calibration.lenslet_images import make_lenslet_image  # noqa: E402


def report(name, grey, lattice, kind, expected_shape=None):
    try:
        fit = _find_lenslet_centres_unchecked(grey, lattice, kind=kind, expected_shape=expected_shape)
    except NoSpotsError as exc:
        print(f"{name:48s} {lattice:4s} {kind:5s} refused already: {exc}", flush=True)
        return None
    rows, cols = fit.shape
    print(f"{name:48s} {lattice:4s} {kind:5s} rms {fit.rms_px:8.4f} px = {fit.rms_px / fit.pitch_px:.5f} pitch; "
          f"pitch {fit.pitch_px:6.2f} px; {len(fit.centres)} kept of {rows} x {cols} = {rows * cols} nodes "
          f"({len(fit.centres) / (rows * cols):.2f}); {fit.rejected} dropped", flush=True)
    return fit.rms_px


def simulated(scale, render):
    from lftransfer.calibration.distortion import collimator_directions
    from lftransfer.rig.requests import Collimator, RealScene, ViewCapture, WhiteField
    from lftransfer.scenes import builtin_scene, load_scene, with_overrides
    from lftransfer.sim.rig import SimRig
    from lftransfer.sim.truth import perturbed_rig

    full = load_scene(builtin_scene("fig4"))
    scene = full if scale == 1 else with_overrides(
        full, rig={"lf_camera": [v // scale for v in full.rig.lf_camera],
                   "projector": [v // scale for v in full.rig.projector], "angular_samples": 16},
        view={"resolution": [v // scale for v in full.view.resolution]})
    truth = perturbed_rig(scene.rig, seed=1)
    rig = SimRig(scene, truth=truth, capture_spp=1)
    levels = truth.camera.levels
    lat, shape = scene.rig.lattice, (scene.rig.rows, scene.rig.cols)
    tag = f"sim fig4 1/{scale}"
    rig.setup(Collimator())
    report(f"{tag} collimator (expected_shape)", to_grey(rig.capture_lf().codes, levels), lat, "spots", shape)
    rig.setup(WhiteField())
    report(f"{tag} white field", to_grey(rig.capture_lf().codes, levels), lat, "white")
    worst = 0.0
    for d in collimator_directions(0.3, 5):
        rig.setup(Collimator(direction=tuple(d)))
        rms = report(f"{tag} collimator tan ({d[0] / d[2]:+.2f}, {d[1] / d[2]:+.2f})",
                     to_grey(rig.capture_lf().codes, levels), lat, "spots")
        worst = max(worst, rms or 0.0)
    print(f"{tag}: worst collimator tilt RMS {worst:.4f} px", flush=True)
    if render:
        rig.setup(RealScene())
        lf = to_grey(rig.capture_lf().codes, levels)
        view = rig.capture_view(ViewCapture()).radiance
        view = to_grey(np.clip(view / max(float(np.percentile(view, 99.5)), 1e-9), 0, 1).astype(np.float32))
        for name, img in ((f"{tag} real scene, LF camera", lf), (f"{tag} real scene, view camera", view)):
            for lattice in ("hex", "rect"):
                for kind in ("spots", "white"):
                    report(name, img, lattice, kind)


def synthetic():
    cases = {("spots", "hex"): (22.0, 3.0, 12), ("spots", "rect"): (36.0, -4.0, 16),
             ("white", "hex"): (30.0, -2.5, 12), ("white", "rect"): (38.0, 4.5, 16)}
    for i, ((kind, lattice), (pitch, rot, bits)) in enumerate(cases.items()):
        for k1 in (-0.07, 0.06):
            im = make_lenslet_image(kind, lattice, shape=(800, 1000), pitch=pitch, rotation_deg=rot, k1=k1,
                                    bits=bits, seed=11 + 4 * i + (k1 < 0))
            report(f"synthetic {kind} k1 {k1:+.2f}", to_grey(im.image, levels=im.levels), lattice, kind)
    for kind in ("spots", "white"):
        im = make_lenslet_image(kind, "hex", shape=(480, 640), pitch=28.0, rotation_deg=-1.0, k1=0.0, seed=13)
        report(f"synthetic {kind} undistorted", to_grey(im.image, levels=im.levels), "hex", kind)


def not_calibration_images():
    photo = Path(__file__).resolve().parents[2] / "src/lftransfer/scenes/textures/photo.png"
    img = cv2.imread(str(photo), cv2.IMREAD_UNCHANGED)
    images = {"texture photo.png": to_grey(img)}
    import matplotlib

    sample = Path(matplotlib.get_data_path()) / "sample_data"
    for name in ("grace_hopper.jpg", "Minduka_Present_Blue_Pack.png"):
        photo = cv2.imread(str(sample / name), cv2.IMREAD_COLOR)
        images[f"photograph {name}"] = to_grey(photo)
        images[f"photograph {name} x2"] = to_grey(cv2.resize(photo, None, fx=2.0, fy=2.0))
    for kind, jitter in (("spots", 0.05), ("white", 0.05), ("spots", 0.02), ("white", 0.02)):
        im = make_lenslet_image(kind, "hex", shape=(480, 640), pitch=28.0, rotation_deg=-1.0, k1=0.0, seed=13,
                                jitter=jitter)
        images[f"synthetic {kind}, centres jittered by {jitter:g} pitch"] = to_grey(im.image, levels=im.levels)
    for sigma in (1.0, 2.0, 4.0, 8.0):
        for seed in (1, 2):
            noise = np.random.default_rng(seed).random((480, 640)).astype(np.float32)
            images[f"random texture sigma {sigma:g} px seed {seed}"] = cv2.GaussianBlur(noise, (0, 0), sigma)
    for name, grey in images.items():
        for lattice in ("hex", "rect"):
            for kind in ("spots", "white"):
                report(name, grey.astype(np.float64), lattice, kind)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--full", action="store_true", help="also the simulated rig at full resolution")
    parser.add_argument("--no-render", action="store_true", help="leave out the real scene's photographs")
    args = parser.parse_args()
    synthetic()
    not_calibration_images()
    simulated(4, not args.no_render)
    if args.full:
        simulated(1, not args.no_render)


if __name__ == "__main__":
    main()

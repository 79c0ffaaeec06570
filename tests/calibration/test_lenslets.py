"""Lenslet centres from collimated-source images: spot detection, sub-pixel centres, lattice fit, files."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest
from scipy.special import ndtr

from lftransfer.calibration.images import CalibrationImageError, read_image, to_grey
from lftransfer.calibration.lenslets import (LatticeFit, NoSpotsError, find_lenslet_centres, lattice_coordinates,
                                             write_centres_csv)

ROW_STEP = {"hex": math.sqrt(3) / 2, "rect": 1.0}


def _ideal(r, c, lattice):
    """Ideal (u, v) of indices, written out independently of the module."""
    u = c + (0.5 * (r % 2) if lattice == "hex" else 0.0)
    return np.stack([u, r * ROW_STEP[lattice]], axis=1)


def _true_homography(lattice, rows, cols, pitch, rot_deg, centre, persp):
    """Ideal lattice (unit pitch) -> pixels: centre the lattice, mild perspective, scale, rotate (CCW on screen)."""
    u0 = (cols - 1) / 2 + (0.25 if lattice == "hex" else 0.0)
    v0 = (rows - 1) / 2 * ROW_STEP[lattice]
    t = np.array([[1, 0, -u0], [0, 1, -v0], [0, 0, 1.0]])
    p = np.array([[1, 0, 0], [0, 1, 0], [persp[0], persp[1], 1.0]])
    a = math.radians(rot_deg)
    s = np.array([[pitch * math.cos(a), pitch * math.sin(a), centre[0]],
                  [-pitch * math.sin(a), pitch * math.cos(a), centre[1]], [0, 0, 1.0]])
    return s @ p @ t


def _map(h, uv):
    q = np.concatenate([uv, np.ones((len(uv), 1))], 1) @ h.T
    return q[:, :2] / q[:, 2:3]


def _render(shape, xy, amp, sigma):
    """Pixel-integrated Gaussian spots (separable: one matrix product)."""
    h, w = shape
    xs, ys = np.arange(w), np.arange(h)
    s = sigma
    gx = ndtr((xs[None] + 0.5 - xy[:, :1]) / s) - ndtr((xs[None] - 0.5 - xy[:, :1]) / s)     # (N, W)
    gy = ndtr((ys[None] + 0.5 - xy[:, 1:]) / s) - ndtr((ys[None] - 0.5 - xy[:, 1:]) / s)     # (N, H)
    norm = (ndtr(0.5 / s) - ndtr(-0.5 / s)) ** 2                                               # peak -> amp
    return gy.T @ (gx * (amp / norm)[:, None])


def _scene(lattice="hex", rows=9, cols=12, pitch=21.0, rot_deg=2.5, shape=(170, 240), persp=(0.004, -0.003),
           sigma=1.3, seed=0, missing=3, noise=True, dim=True, shift=(4.0, -6.0)):
    """A noisy, vignetted spot image of a lattice seen at a tilt, with holes, clipped spots and a dim spot.

    Returns:
        image (H, W) float64, truth centres (M, 2) of the visible spots, their true (row, col) (M, 2), and
        the true homography.
    """
    rng = np.random.default_rng(seed)
    h, w = shape
    hom = _true_homography(lattice, rows, cols, pitch, rot_deg, ((w - 1) / 2 + shift[0], (h - 1) / 2 + shift[1]), persp)
    r, c = np.divmod(np.arange(rows * cols), cols)
    xy = _map(hom, _ideal(r, c, lattice))
    inset = np.minimum(np.minimum(xy[:, 0], w - 1 - xy[:, 0]), np.minimum(xy[:, 1], h - 1 - xy[:, 1]))
    clipped = (inset <= 0.5) & (inset > -3)                      # cut by the border (centre outside or on it)
    visible = inset >= 5.0
    assert clipped.sum() >= 3 and visible.sum() >= 40
    interior = np.flatnonzero(inset > 3 * pitch)
    holes = rng.choice(interior, missing, replace=False) if missing else np.array([], int)
    visible[holes] = False
    drawn = visible | clipped                                     # nothing half-way (ambiguous) is drawn
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
    vig = 1 - 0.5 * (((xx - w / 2) ** 2 + (yy - h / 2) ** 2) / ((w / 2) ** 2 + (h / 2) ** 2))
    amp = np.full(len(xy), 0.6)
    if dim:
        corner = np.flatnonzero(visible)[np.argmax(np.hypot(xy[visible, 0] - w / 2, xy[visible, 1] - h / 2))]
        amp[corner] *= 0.4                                       # with vignetting: ~20 % of the brightest
    img = _render(shape, xy[drawn], amp[drawn], sigma)
    img += 0.03 + 0.04 * np.exp(-((xx - 0.3 * w) ** 2 + (yy - 0.7 * h) ** 2) / (2 * (0.3 * w) ** 2))   # uneven
    img *= vig
    if noise:
        img = rng.poisson(img * 4000) / 4000 + rng.normal(0, 0.003, img.shape)
    return img, xy[visible], np.stack([r, c], 1)[visible], hom


def _match(found, truth, tol=1.0):
    """For each truth spot, the index of the found centre within ``tol`` px (or -1)."""
    d = np.linalg.norm(truth[:, None] - found[None], axis=-1)
    j = d.argmin(axis=1)
    return np.where(d[np.arange(len(truth)), j] < tol, j, -1)


def _expected_indices(true_idx, lattice):
    """The module's convention: top detected row is row 0, leftmost column (in that parity) column 0."""
    r = true_idx[:, 0] - true_idx[:, 0].min()
    if lattice == "hex":
        u2 = 2 * true_idx[:, 1] + true_idx[:, 0] % 2
        c2 = u2 - r % 2
        return np.stack([r, (c2 - c2.min()) // 2], 1)
    return np.stack([r, true_idx[:, 1] - true_idx[:, 1].min()], 1)


def _pitch_rotation(hom, shape):
    """Along-row spacing and row direction (deg CCW on screen) of a homography at the image centre."""
    h, w = shape
    target = np.array([(w - 1) / 2, (h - 1) / 2])
    uv = _map(np.linalg.inv(hom), target[None])[0]
    eps = 1e-4
    d = (_map(hom, (uv + [eps, 0])[None])[0] - _map(hom, (uv - [eps, 0])[None])[0]) / (2 * eps)
    return math.hypot(*d), math.degrees(math.atan2(-d[1], d[0]))


@pytest.mark.parametrize("sigma", [1.0, 1.5, 2.0])
def test_01_clean_spots_subpixel(sigma):
    rng = np.random.default_rng(int(sigma * 10))
    pitch = 16.0
    r, c = np.divmod(np.arange(6 * 8), 8)
    truth = np.stack([20 + c * pitch, 18 + r * pitch], 1) + rng.uniform(-0.5, 0.5, (48, 2))
    img = _render((120, 150), truth, np.full(48, 0.8), sigma)
    fit = find_lenslet_centres(img, "rect")
    j = _match(fit.centres, truth)
    assert len(fit.centres) == 48 and np.all(j >= 0)
    assert np.abs(fit.centres[j] - truth).max() <= 0.05
    assert abs(fit.spot_sigma_px - math.sqrt(sigma ** 2 + 1 / 12)) < 0.2


@pytest.mark.parametrize("seed", [0, 1])
def test_02_hex_noisy_tilted_vignetted(seed):
    img, truth, true_idx, hom = _scene("hex", seed=seed)
    fit = find_lenslet_centres(img, "hex")
    assert isinstance(fit, LatticeFit) and fit.lattice == "hex"
    assert len(fit.centres) == len(truth)                        # every visible spot, nothing else
    j = _match(fit.centres, truth)
    assert np.all(j >= 0)
    err = np.linalg.norm(fit.centres[j] - truth, axis=1)
    assert np.sqrt(np.mean(err ** 2)) <= 0.1 and np.median(err) <= 0.05
    pitch, rot = _pitch_rotation(hom, img.shape)
    assert abs(fit.pitch_px / pitch - 1) <= 0.002
    assert abs(fit.rotation_deg - rot) <= 0.05
    np.testing.assert_array_equal(fit.indices[j], _expected_indices(true_idx, "hex"))
    # row-major order, predicted lattice, residuals against the homography
    assert np.all(np.diff(fit.indices[:, 0] * 1000 + fit.indices[:, 1]) > 0)
    np.testing.assert_allclose(fit.residuals, fit.centres - fit.predicted(fit.indices), atol=1e-9)
    assert fit.rms_px < 0.1 and fit.max_residual_px < 0.3
    np.testing.assert_allclose(fit.origin, fit.predicted(np.array([[0, 0]]))[0])
    assert fit.indices.min() == 0


def test_03_odd_top_row_and_dim_spot():
    """Row 0 of the array is clipped off the top: the detected top row is an odd row."""
    img, truth, true_idx, _ = _scene("hex", rows=10, shape=(175, 230), seed=3, persp=(0.0, 0.004))
    assert true_idx[:, 0].min() % 2 == 1
    fit = find_lenslet_centres(img, "hex")
    j = _match(fit.centres, truth)
    assert len(fit.centres) == len(truth) and np.all(j >= 0)
    expected = _expected_indices(true_idx, "hex")
    np.testing.assert_array_equal(fit.indices[j], expected)
    assert expected[expected[:, 0] == 0, 1].min() == 1           # the shifted top row starts in column 1
    # Knowing the array's shape, the indices of an array seen whole but for its clipped row 0 are its own.
    img, truth, true_idx, _ = _scene("hex", rows=10, cols=9, rot_deg=1.0, shape=(175, 230), seed=7,
                                     persp=(0.0, 0.002), shift=(0.0, -6.0))
    assert true_idx[:, 0].min() == 1 and true_idx[:, 1].max() == 8
    fit = find_lenslet_centres(img, "hex", expected_shape=(10, 9))
    j = _match(fit.centres, truth)
    assert len(fit.centres) == len(truth) and np.all(j >= 0)
    np.testing.assert_array_equal(fit.indices[j], true_idx)
    assert fit.shape == (10, 9) and "array: 10 x 9" in fit.summary()


def test_04_rect_lattice():
    img, truth, true_idx, hom = _scene("rect", rows=8, cols=11, pitch=22.0, rot_deg=-3.0, shape=(170, 230), seed=4)
    fit = find_lenslet_centres(img, "rect")
    j = _match(fit.centres, truth)
    assert len(fit.centres) == len(truth) and np.all(j >= 0)
    err = np.linalg.norm(fit.centres[j] - truth, axis=1)
    assert np.sqrt(np.mean(err ** 2)) <= 0.1
    pitch, rot = _pitch_rotation(hom, img.shape)
    assert abs(fit.pitch_px / pitch - 1) <= 0.002 and abs(fit.rotation_deg - rot) <= 0.05
    np.testing.assert_array_equal(fit.indices[j], _expected_indices(true_idx, "rect"))
    # The wrong lattice kind is refused rather than mis-indexed.
    with pytest.raises(NoSpotsError, match="hex lattice"):
        find_lenslet_centres(img, "hex")


def test_05_hot_pixels_and_uint16_input():
    img, truth, _, _ = _scene("hex", seed=5)
    img[40, 60] = img[100, 17] = img[150, 200] = 1.0             # hot pixels, off the lattice or not
    codes = np.round(np.clip(img, 0, 1) * 4095).astype(np.uint16)
    fit = find_lenslet_centres(np.repeat(codes[..., None], 3, axis=2), "hex")
    assert len(fit.centres) == len(truth) and np.all(_match(fit.centres, truth) >= 0)


def test_06_no_spots():
    with pytest.raises(NoSpotsError, match="no lenslet spots"):
        find_lenslet_centres(np.zeros((50, 60)), "hex")
    with pytest.raises(NoSpotsError, match="no lenslet spots"):
        find_lenslet_centres(np.random.default_rng(0).normal(0.1, 0.01, (80, 90)), "hex")
    three = _render((60, 80), np.array([[20.0, 20], [40, 20], [30, 37.3]]), np.ones(3), 1.2)
    with pytest.raises(NoSpotsError, match="at least 4"):
        find_lenslet_centres(three, "hex")
    line = _render((60, 160), np.stack([np.arange(10, 150, 20.0), np.full(7, 30.0)], 1), np.ones(7), 1.2)
    with pytest.raises(NoSpotsError):
        find_lenslet_centres(line, "rect")
    with pytest.raises(ValueError, match="lattice"):
        find_lenslet_centres(three, "square")
    img, *_ = _scene("hex", seed=0)
    with pytest.raises(NoSpotsError, match="expected 4 x 4"):
        find_lenslet_centres(img, "hex", expected_shape=(4, 4))


def test_07_csv_round_trip(tmp_path):
    img, truth, _, _ = _scene("hex", seed=6)
    fit = find_lenslet_centres(img, "hex")
    out = tmp_path / "sub" / "centres.csv"
    write_centres_csv(out, fit)
    lines = out.read_text().splitlines()
    assert lines[0] == "x,y" and len(lines) == 1 + len(truth)
    values = np.array([[float(v) for v in line.split(",")] for line in lines[1:]])
    np.testing.assert_allclose(values, fit.centres, atol=6e-5)
    assert all(len(v.split(".")[1]) == 4 for v in lines[1].split(","))
    assert sorted(p.name for p in out.parent.iterdir()) == ["centres.csv"]          # no temporary file left
    text = fit.summary()
    assert "hex" in text and str(len(truth)) in text and "pitch" in text and "RMS" in text
    np.testing.assert_allclose(lattice_coordinates([[1, 2], [2, 2]], "hex"), [[2.5, math.sqrt(3) / 2],
                                                                             [2.0, math.sqrt(3)]])


@pytest.mark.parametrize("ext", ["png", "tiff"])
@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
@pytest.mark.parametrize("channels", [0, 3, 4])
def test_08_read_image_formats(tmp_path, ext, dtype, channels):
    full = np.iinfo(dtype).max
    grey = (np.arange(12 * 10).reshape(10, 12) * (full // 200)).astype(dtype)
    data = grey if channels == 0 else np.dstack([grey, grey // 2, grey // 4] + ([np.full_like(grey, 7)]
                                                                               if channels == 4 else []))
    path = tmp_path / f"img.{ext}"
    assert cv2.imwrite(str(path), data)
    img = read_image(path)
    assert img.dtype == np.float64 and img.shape == (10, 12)
    colour = grey.astype(np.float64) if channels == 0 else (grey.astype(np.float64) + grey // 2 + grey // 4) / 3
    np.testing.assert_allclose(img, colour / full, atol=1e-12)


def test_09_to_grey_and_read_errors(tmp_path):
    codes = np.full((4, 5, 3), 4095, np.uint16)
    np.testing.assert_allclose(to_grey(codes, levels=4095), 1.0)
    np.testing.assert_allclose(to_grey(codes), 4095 / 65535)
    np.testing.assert_allclose(to_grey(np.full((3, 3), 0.25, np.float32)), 0.25)
    for bad in (np.zeros((3, 3, 5), np.uint8), np.zeros((3,), np.uint8), np.zeros((3, 3), np.int32)):
        with pytest.raises(CalibrationImageError, match="expected"):
            to_grey(bad)
    missing = tmp_path / "missing.png"
    with pytest.raises(CalibrationImageError, match="missing.png.*no such file.*PNG or TIFF"):
        read_image(missing)
    with pytest.raises(CalibrationImageError, match="not a file"):
        read_image(tmp_path)
    notes = tmp_path / "notes.tiff"
    notes.write_text("not an image")
    with pytest.raises(CalibrationImageError, match="notes.tiff.*not a readable image.*8- or 16-bit"):
        read_image(notes)
    floats = tmp_path / "float.tiff"
    assert cv2.imwrite(str(floats), np.zeros((5, 5), np.float32))
    with pytest.raises(CalibrationImageError, match="float.tiff.*float32"):
        read_image(floats)


def test_10_simulated_rig(variant):
    """The simulator's collimated-source image (quick fig4 rig, perturbed truth): every lenslet to < 0.1 px."""
    from lftransfer.rig.sim import SimRig
    from lftransfer.rig.truth import perturbed_rig
    from lftransfer.scenes import builtin_scene, load_scene, with_overrides

    full = load_scene(builtin_scene("fig4"))
    # The devices at a quarter size, as ``lftransfer.pipeline.quick_scene`` makes them (LF camera 512 x 384,
    # 10 x 12 hex lenslets about 39 px apart); built here to keep this test off the pipeline's imports.
    scene = with_overrides(full, rig={"lf_camera": [v // 4 for v in full.rig.lf_camera],
                                      "projector": [v // 4 for v in full.rig.projector], "angular_samples": 16})
    truth = perturbed_rig(scene.rig, seed=1)
    raw = SimRig(scene, truth=truth, capture_spp=1).capture_collimated()
    assert raw.shape == (384, 512, 3) and raw.dtype == np.uint16
    K = truth.array.K
    spots = truth.camera.device.ray_to_pixel(truth.array, np.arange(K), np.tile([0.0, 0.0, 1.0], (K, 1)))
    fit = find_lenslet_centres(to_grey(raw, levels=4095), scene.rig.lattice,
                               expected_shape=(scene.rig.rows, scene.rig.cols))
    assert len(fit.centres) == K == 120 and fit.shape == (10, 12)
    k = fit.indices[:, 0] * scene.rig.cols + fit.indices[:, 1]                  # the array's own numbering
    np.testing.assert_array_equal(k, np.arange(K))
    err = np.linalg.norm(fit.centres - spots, axis=1)
    assert np.sqrt(np.mean(err ** 2)) <= 0.1
    assert fit.rms_px < 0.1                                      # the spots are a homography of the lattice

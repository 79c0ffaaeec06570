"""Chessboard intrinsics calibration against synthetic photographs of a hidden camera.

The photographs are rendered by inverse mapping: every sub-pixel sample is undistorted (iteratively inverting
OpenCV's k1 k2 p1 p2 k3 model) to a ray, the ray is intersected with the board plane, and the square parity
decides black or white; 3 x 3 supersampling anti-aliases the edges. A white margin surrounds the board and a
grey table surrounds the margin. The images are then blurred, given noise and quantised, and written as 8-bit
grey, 16-bit grey and 8-bit colour PNGs.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import cv2
import numpy as np
import pytest

from lftransfer.calibration.intrinsics import (
    Intrinsics,
    IntrinsicsError,
    calibrate_intrinsics,
    find_chessboard,
    parse_pattern,
    write_intrinsics_json,
)

W, H = 640, 480
FX, FY = 604.0, 601.0
CX, CY = 323.5, 236.0  # the image centre is (319.5, 239.5)
K_TRUE = np.array([[FX, 0.0, CX], [0.0, FY, CY], [0.0, 0.0, 1.0]])
DIST_TRUE = np.array([-0.2, 0.05, 0.0012, -0.0008, 0.0])  # k1 k2 p1 p2 k3
PATTERN = (9, 6)  # inner corners: a board of 10 x 7 squares
SQUARE_M = 0.025
SUPER = 3

# (rx, ry, rz) degrees, board centre (x, y, z) in the camera frame, metres: tilts of 20-39 degrees in ten
# directions, distances of 0.27-0.37 m, the board pushed towards every part of the frame so that the
# distortion is well sampled (every inner corner stays >= 30 px inside the frame).
POSES = [
    ((34.3, 17.9, 5.9), (-0.023, -0.014, 0.276)),
    ((12.4, 31.4, -2.3), (0.059, 0.057, 0.371)),
    ((-2.8, 20.5, -6.9), (-0.051, 0.030, 0.290)),
    ((-18.1, 22.9, 0.4), (0.060, -0.044, 0.363)),
    ((-17.5, 11.2, 3.2), (0.011, 0.015, 0.270)),
    ((-22.8, -2.9, 12.4), (-0.041, 0.027, 0.361)),
    ((-20.6, -26.5, 1.1), (-0.008, 0.021, 0.279)),
    ((8.3, -31.9, -12.7), (-0.012, -0.041, 0.366)),
    ((10.4, -17.3, 6.6), (-0.015, 0.026, 0.280)),
    ((31.4, -12.0, 2.1), (0.043, -0.042, 0.368)),
]


def _rotation(rx: float, ry: float, rz: float) -> np.ndarray:
    a, b, c = np.radians([rx, ry, rz])
    Rx = np.array([[1, 0, 0], [0, math.cos(a), -math.sin(a)], [0, math.sin(a), math.cos(a)]])
    Ry = np.array([[math.cos(b), 0, math.sin(b)], [0, 1, 0], [-math.sin(b), 0, math.cos(b)]])
    Rz = np.array([[math.cos(c), -math.sin(c), 0], [math.sin(c), math.cos(c), 0], [0, 0, 1]])
    return Rz @ Ry @ Rx


def _pose(angles, centre) -> tuple[np.ndarray, np.ndarray]:
    """Board-to-camera (R, t) putting the middle of the inner-corner grid at ``centre``."""
    R = _rotation(*angles)
    mid = np.array([(PATTERN[0] - 1) / 2 * SQUARE_M, (PATTERN[1] - 1) / 2 * SQUARE_M, 0.0])
    return R, np.asarray(centre, float) - R @ mid


def _rays() -> tuple[np.ndarray, np.ndarray]:
    """Undistorted normalised coordinates (x, y) of every sub-pixel sample, shape (H*S, W*S) each."""
    offs = (np.arange(SUPER) + 0.5) / SUPER - 0.5
    u = (np.arange(W)[:, None] + offs[None, :]).ravel()
    v = (np.arange(H)[:, None] + offs[None, :]).ravel()
    uu, vv = np.meshgrid(u, v)
    xd, yd = (uu - CX) / FX, (vv - CY) / FY
    k1, k2, p1, p2, k3 = DIST_TRUE
    x, y = xd.copy(), yd.copy()
    for _ in range(40):
        r2 = x * x + y * y
        radial = 1 + k1 * r2 + k2 * r2**2 + k3 * r2**3
        dx = 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
        dy = p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
        x, y = (xd - dx) / radial, (yd - dy) / radial
    r2 = x * x + y * y
    radial = 1 + k1 * r2 + k2 * r2**2 + k3 * r2**3
    xr = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
    yr = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
    assert max(np.abs(xr - xd).max() * FX, np.abs(yr - yd).max() * FY) < 1e-6  # the inversion converged
    return x, y


def _true_corners(R: np.ndarray, t: np.ndarray) -> np.ndarray:
    cols, rows = PATTERN
    obj = np.zeros((cols * rows, 3))
    obj[:, :2] = np.mgrid[0:cols, 0:rows].T.reshape(-1, 2) * SQUARE_M
    proj, _ = cv2.projectPoints(obj, cv2.Rodrigues(R)[0], t, K_TRUE, DIST_TRUE)
    return proj.reshape(-1, 2)


def _render(rays, R: np.ndarray, t: np.ndarray, rng: np.random.Generator, board: bool = True) -> np.ndarray:
    """(H, W) float image in [0, 1] of the board (or, with ``board=False``, of the blank white card)."""
    x, y = rays
    n = R[:, 2]
    denom = n[0] * x + n[1] * y + n[2]
    s = (n @ t) / denom
    px, py, pz = s * x - t[0], s * y - t[1], s - t[2]
    bu = (R[0, 0] * px + R[1, 0] * py + R[2, 0] * pz) / SQUARE_M
    bv = (R[0, 1] * px + R[1, 1] * py + R[2, 1] * pz) / SQUARE_M
    cols, rows = PATTERN
    on_board = (bu >= -1) & (bu < cols) & (bv >= -1) & (bv < rows)
    on_card = (bu >= -2) & (bu < cols + 1) & (bv >= -2) & (bv < rows + 1) & (s > 0)
    black = on_board & ((np.floor(bu) + np.floor(bv)) % 2 == 0)
    if not board:
        black[:] = False
    val = np.where(on_card, np.where(black, 0.07, 0.92), 0.45)
    img = val.reshape(H, SUPER, W, SUPER).mean(axis=(1, 3))
    img = cv2.GaussianBlur(img, (0, 0), 0.6)
    img = img + rng.normal(0.0, 0.008, img.shape)
    return np.clip(img, 0.0, 1.0)


def _write(path: Path, img: np.ndarray, kind: str) -> Path:
    if kind == "gray8":
        data = np.round(img * 255).astype(np.uint8)
    elif kind == "gray16":  # 12-bit sensor data in a 16-bit container
        data = (np.round(img * 4095).astype(np.uint16) * 16).astype(np.uint16)
    elif kind == "bgr8":
        tint = np.array([0.93, 1.0, 0.97])  # a slightly warm white balance
        data = np.round(img[:, :, None] * tint * 255).astype(np.uint8)
    else:  # pragma: no cover
        raise AssertionError(kind)
    assert cv2.imwrite(str(path), data)
    return path


@pytest.fixture(scope="module")
def board_set(tmp_path_factory):
    """Ten photographs of the board (mixed PNG flavours), one blank card, and the true corners of each view."""
    folder = tmp_path_factory.mktemp("chessboards")
    rng = np.random.default_rng(1234)
    rays = _rays()
    kinds = ["gray8", "gray16", "bgr8"]
    paths, corners, images = [], [], []
    for i, (angles, centre) in enumerate(POSES):
        R, t = _pose(angles, centre)
        truth = _true_corners(R, t)
        # the whole inner grid comfortably inside the frame
        assert truth[:, 0].min() > 30 and truth[:, 0].max() < W - 30, i
        assert truth[:, 1].min() > 30 and truth[:, 1].max() < H - 30, i
        img = _render(rays, R, t, rng)
        paths.append(_write(folder / f"view{i:02d}.png", img, kinds[i % 3]))
        corners.append(truth)
        images.append(img)
    R, t = _pose(*POSES[0])
    blank = _write(folder / "blank.png", _render(rays, R, t, rng, board=False), "gray8")
    return {"folder": folder, "paths": paths, "corners": corners, "images": images, "blank": blank}


def _corner_errors(found: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """(N,) corner position errors (px), allowing for the detector's 180-degree ordering ambiguity."""
    e1 = np.linalg.norm(found - truth, axis=1)
    e2 = np.linalg.norm(found[::-1] - truth, axis=1)
    return e1 if e1.max() <= e2.max() else e2


def test_find_chessboard_subpixel_on_all_depths(board_set):
    img = board_set["images"][1]
    truth = board_set["corners"][1]
    for arr in (
        np.round(img * 255).astype(np.uint8),
        (np.round(img * 4095) * 16).astype(np.uint16),
        np.repeat(np.round(img * 255).astype(np.uint8)[:, :, None], 3, axis=2),
        img.astype(np.float32),
    ):
        found = find_chessboard(arr, PATTERN)
        assert found is not None, arr.dtype
        assert found.shape == (54, 2) and found.dtype == np.float32
        err = _corner_errors(found, truth)
        assert np.sqrt(np.mean(err**2)) < 0.15 and err.max() < 0.5, (arr.dtype, arr.shape)


def test_find_chessboard_none_without_board(board_set):
    blank = cv2.imread(str(board_set["blank"]), cv2.IMREAD_UNCHANGED)
    assert find_chessboard(blank, PATTERN) is None
    img = np.round(board_set["images"][0] * 255).astype(np.uint8)
    assert find_chessboard(img, (12, 9)) is None


def test_calibration_recovers_hidden_camera(board_set):
    paths = board_set["paths"] + [board_set["blank"]]
    intr = calibrate_intrinsics(paths, PATTERN, SQUARE_M)
    K, d = intr.camera_matrix, intr.dist_coeffs
    assert intr.image_size == (W, H)
    assert K.shape == (3, 3) and d.shape == (5,)
    assert abs(K[0, 0] / FX - 1) < 0.005, K
    assert abs(K[1, 1] / FY - 1) < 0.005, K
    assert abs(K[0, 2] - CX) < 2.0 and abs(K[1, 2] - CY) < 2.0, K
    assert abs(d[0] - DIST_TRUE[0]) < 0.02, d
    assert intr.rms_px < 0.3
    assert len(intr.per_view_rms_px) == len(intr.used) == len(board_set["paths"])
    assert max(intr.per_view_rms_px) < 0.4
    assert intr.used == [str(p) for p in board_set["paths"]]
    assert list(intr.skipped) == [str(board_set["blank"])]
    reason = intr.skipped[str(board_set["blank"])]
    assert "blank.png" in reason and "9x6" in reason
    # the distortion of the hidden lens is several pixels at the frame's edge: the data does exercise it
    truth = board_set["corners"][0]
    ideal = cv2.undistortPoints(truth.reshape(-1, 1, 2), K_TRUE, DIST_TRUE, P=K_TRUE).reshape(-1, 2)
    assert np.abs(truth - ideal).max() > 5


def test_two_valid_views_is_an_error(board_set):
    paths = board_set["paths"][:2] + [board_set["blank"]]
    with pytest.raises(IntrinsicsError, match="at least 3") as exc:
        calibrate_intrinsics(paths, PATTERN, SQUARE_M)
    assert "blank.png" in str(exc.value)


def test_impossible_pattern_skips_every_view(board_set):
    with pytest.raises(IntrinsicsError, match="12x9") as exc:
        calibrate_intrinsics(board_set["paths"][:4], (12, 9), SQUARE_M)
    assert "only 0 usable" in str(exc.value)
    assert "view00.png" in str(exc.value)


def test_unreadable_files_name_the_file(board_set, tmp_path):
    fake = tmp_path / "notes.png"
    fake.write_text("this is not a PNG\n")
    with pytest.raises(IntrinsicsError, match="notes.png"):
        calibrate_intrinsics(board_set["paths"][:3] + [fake], PATTERN, SQUARE_M)
    missing = tmp_path / "missing.png"
    with pytest.raises(IntrinsicsError, match="missing.png"):
        calibrate_intrinsics([missing] + board_set["paths"][:3], PATTERN, SQUARE_M)


def test_images_of_different_sizes(board_set, tmp_path):
    small = tmp_path / "small.png"
    img = cv2.imread(str(board_set["paths"][0]), cv2.IMREAD_UNCHANGED)
    cv2.imwrite(str(small), cv2.resize(img, (320, 240), interpolation=cv2.INTER_AREA))
    with pytest.raises(IntrinsicsError, match="small.png") as exc:
        calibrate_intrinsics(board_set["paths"][:3] + [small], PATTERN, SQUARE_M)
    assert "320x240" in str(exc.value) and "640x480" in str(exc.value)


def test_no_images_and_bad_arguments():
    with pytest.raises(IntrinsicsError):
        calibrate_intrinsics([], PATTERN, SQUARE_M)
    with pytest.raises(ValueError):
        calibrate_intrinsics(["x.png"], PATTERN, 0.0)
    with pytest.raises(ValueError):
        calibrate_intrinsics(["x.png"], (1, 6), SQUARE_M)


@pytest.mark.parametrize(
    "text,expected", [("9x6", (9, 6)), ("9X6", (9, 6)), (" 7 x 5 ", (7, 5)), ("11\u00d78", (11, 8))]
)
def test_parse_pattern_good(text, expected):
    assert parse_pattern(text) == expected


@pytest.mark.parametrize("text", ["", "9", "9x", "x6", "9x6x2", "nine by six", "9.5x6", "-9x6", "1x6", "9x0"])
def test_parse_pattern_bad(text):
    with pytest.raises(ValueError, match="pattern"):
        parse_pattern(text)


def test_write_intrinsics_json(tmp_path):
    intr = Intrinsics(
        image_size=(640, 480),
        camera_matrix=K_TRUE.copy(),
        dist_coeffs=DIST_TRUE.copy(),
        rms_px=0.123,
        per_view_rms_px=[0.1, 0.12, 0.14],
        used=["a.png", "b.png", "c.png"],
        skipped={"d.png": "chessboard pattern 9x6 (inner corners) not found in image 'd.png'"},
    )
    out = tmp_path / "sub" / "intrinsics.json"
    out.parent.mkdir()
    out.write_text("old contents")
    write_intrinsics_json(out, intr)
    data = json.loads(out.read_text())
    assert set(data) == {"rms_px", "camera_matrix", "dist_coeffs", "image_size", "per_view_rms_px", "used", "skipped"}
    assert data["rms_px"] == pytest.approx(0.123)
    assert np.allclose(data["camera_matrix"], K_TRUE) and len(data["camera_matrix"]) == 3
    assert np.allclose(data["dist_coeffs"], DIST_TRUE) and len(data["dist_coeffs"]) == 5
    assert data["image_size"] == [640, 480]
    assert data["used"] == ["a.png", "b.png", "c.png"]
    assert "d.png" in data["skipped"]
    assert [p.name for p in out.parent.iterdir()] == ["intrinsics.json"]  # no temporary file left behind

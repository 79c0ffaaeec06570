"""`lft calibrate lenslets` and `lft calibrate intrinsics` on image files, good and bad."""

from __future__ import annotations

import json

import cv2
import numpy as np
from typer.testing import CliRunner

from lftransfer.app.cli import app

runner = CliRunner()


def _text(result) -> str:
    return " ".join((result.output or "").split())


def _spots(path, pitch=24.0, rows=6, cols=8, bits=16):
    """A hexagonal lattice of Gaussian spots, vignetted, noisy, written as a PNG."""
    h, w = int(rows * pitch * 0.87 + 2 * pitch), int(cols * pitch + 2 * pitch)
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
    img = np.zeros((h, w))
    truth = []
    for r in range(rows):
        for c in range(cols):
            x = pitch * (1.3 + c + 0.5 * (r % 2))
            y = pitch * (1.2 + r * np.sqrt(3) / 2)
            truth.append((x, y))
            img += np.exp(-((xx - x) ** 2 + (yy - y) ** 2) / (2 * 1.5 ** 2))
    img *= 1 - 0.5 * (((xx - w / 2) ** 2 + (yy - h / 2) ** 2) / ((w / 2) ** 2 + (h / 2) ** 2))
    img += np.random.default_rng(0).normal(0, 0.01, img.shape)
    levels = 2 ** bits - 1
    cv2.imwrite(str(path), np.round(np.clip(img * 0.8, 0, 1) * levels).astype(np.uint16 if bits > 8 else np.uint8))
    return np.array(truth)


def test_01_lenslets_writes_centres(tmp_path):
    truth = _spots(tmp_path / "spots.png")
    out = tmp_path / "centres.csv"
    result = runner.invoke(app, ["calibrate", "lenslets", str(tmp_path / "spots.png"), "--lattice", "hex",
                                 "--out", str(out)])
    assert result.exit_code == 0, result.output
    lines = out.read_text().splitlines()
    assert lines[0] == "x,y" and len(lines) == 1 + len(truth)
    found = np.array([[float(v) for v in line.split(",")] for line in lines[1:]])
    d = np.linalg.norm(found[:, None] - truth[None], axis=-1).min(axis=1)
    assert d.max() < 0.2


def test_02_lenslets_bad_input(tmp_path):
    text = tmp_path / "notes.png"
    text.write_text("not an image")
    result = runner.invoke(app, ["calibrate", "lenslets", str(text), "--out", str(tmp_path / "c.csv")])
    assert result.exit_code == 2 and "notes.png" in _text(result)
    black = tmp_path / "black.png"
    cv2.imwrite(str(black), np.zeros((50, 60), np.uint8))
    result = runner.invoke(app, ["calibrate", "lenslets", str(black), "--out", str(tmp_path / "c.csv")])
    assert result.exit_code == 2 and "black.png" in _text(result)
    assert not (tmp_path / "c.csv").exists()
    result = runner.invoke(app, ["calibrate", "lenslets", str(black), "--lattice", "square"])
    assert result.exit_code == 2 and "--lattice" in _text(result)


def _board_views(tmp_path, n=6):
    """Chessboard photographs (10 x 7 squares: 9 x 6 inner corners) seen through homographies."""
    sq = 40
    board = np.kron((np.add.outer(np.arange(7), np.arange(10)) % 2).astype(np.uint8) * 255,
                    np.ones((sq, sq), np.uint8))
    board = cv2.copyMakeBorder(board, sq, sq, sq, sq, cv2.BORDER_CONSTANT, value=255)
    paths = []
    rng = np.random.default_rng(1)
    h, w = board.shape
    for i in range(n):
        src = np.float32([[0, 0], [w, 0], [w, h], [0, h]])
        dst = np.float32([[60, 50], [580, 40], [600, 430], [40, 450]]) + rng.uniform(-35, 35, (4, 2)).astype(np.float32)
        view = cv2.warpPerspective(board, cv2.getPerspectiveTransform(src, dst), (640, 480), borderValue=200)
        paths.append(tmp_path / f"view{i}.png")
        cv2.imwrite(str(paths[-1]), cv2.GaussianBlur(view, (3, 3), 0.7))
    return paths


def test_03_intrinsics_writes_json(tmp_path):
    paths = _board_views(tmp_path)
    blank = tmp_path / "blank.png"
    cv2.imwrite(str(blank), np.full((480, 640), 128, np.uint8))
    out = tmp_path / "intrinsics.json"
    result = runner.invoke(app, ["calibrate", "intrinsics", *map(str, paths), str(blank), "--pattern", "9x6",
                                 "--square-mm", "25", "--out", str(out)])
    assert result.exit_code == 0, result.output
    data = json.loads(out.read_text())
    assert {"rms_px", "camera_matrix", "dist_coeffs"} <= set(data)
    assert len(data["dist_coeffs"]) == 5 and np.array(data["camera_matrix"]).shape == (3, 3)
    assert "blank.png" in _text(result)         # skipped, with the reason


def test_04_intrinsics_bad_input(tmp_path):
    paths = _board_views(tmp_path, n=3)
    result = runner.invoke(app, ["calibrate", "intrinsics", *map(str, paths), "--pattern", "nine",
                                 "--square-mm", "25"])
    assert result.exit_code == 2
    result = runner.invoke(app, ["calibrate", "intrinsics", *map(str, paths), "--pattern", "12x9",
                                 "--square-mm", "25", "--out", str(tmp_path / "i.json")])
    assert result.exit_code == 2 and not (tmp_path / "i.json").exists()
    result = runner.invoke(app, ["calibrate", "intrinsics", str(tmp_path / "missing.png"), "--square-mm", "25"])
    assert result.exit_code == 2 and "missing.png" in _text(result)


def test_05_calibrate_scene_writes_file_report_and_errors(variant, tmp_path):
    """``lft calibrate SCENE.toml --out F`` calibrates the simulated rig and writes the file, report and errors."""
    from lftransfer.scenes import builtin_scene

    out = tmp_path / "cal" / "calibration.json"
    result = runner.invoke(app, ["calibrate", str(builtin_scene("fig4")), "--quick", "--truth-seed", "2",
                                 "--out", str(out)])
    assert result.exit_code == 0, result.output
    data = json.loads(out.read_text())
    assert data["format"] == "lftransfer-calibration/1" and len(data["lf_camera"]["lenslets"]) == 120
    errors = json.loads((out.parent / "calibration_errors.json").read_text())
    assert errors["lenslet_centre_rms_px"] < 0.1
    assert (out.parent / "calibration_report.html").stat().st_size > 10_000


def test_06_calibrate_scene_bad_input(tmp_path):
    result = runner.invoke(app, ["calibrate", str(tmp_path / "nope.toml")])
    assert result.exit_code == 2 and "nope.toml" in _text(result)
    bad = tmp_path / "bad.toml"
    bad.write_text("[rig]\nrows = -3\n")
    result = runner.invoke(app, ["calibrate", str(bad)])
    assert result.exit_code == 2 and "bad.toml" in _text(result) and "rows" in _text(result)


def test_07_lenslets_refuses_a_poor_fit(tmp_path):
    """Blobs off the lattice at random (not a lens array's image): one line saying why, no centres written."""
    from .lenslet_images import make_lenslet_image

    im = make_lenslet_image("spots", "hex", shape=(480, 640), pitch=28.0, rotation_deg=-1.0, k1=0.0, seed=13,
                            jitter=0.02)
    cv2.imwrite(str(tmp_path / "scene.png"), im.image)
    result = runner.invoke(app, ["calibrate", "lenslets", str(tmp_path / "scene.png"), "--lattice", "hex",
                                 "--out", str(tmp_path / "c.csv")])
    text = _text(result)
    assert result.exit_code == 2 and "scene.png" in text and "poor lattice fit" in text, result.output
    assert "expected a spot image or a white image of the lens array" in text
    assert not (tmp_path / "c.csv").exists()

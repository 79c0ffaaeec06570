"""Test light fields of known depth rendered on the simulated rig (lftransfer.sim.views, ``lft sim views``).

What each test shows:
- test_01: on Fig. 6's real checkerboard and meshes (focused at infinity: every disparity positive), the view
  grid's true disparity is what the plane sweep of
  ``lft depth`` finds where the centre view has texture (median error under 0.1 px per view step), and the grid
  read in the wrong order (rows and columns reversed: every offset negated) is found wrong by five times more (the
  negative control: the truth is not something any estimate matches); a sensor shift of one pixel per view step
  puts the focus plane at f B and lowers every disparity by one.
- test_02: ``lft sim views`` writes the benchmark's layout, which ``lft depth --truth`` reads and scores.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.ndimage import sobel

from lftransfer.lightfield.disparity import estimate_disparity
from lftransfer.lightfield.view_grid import read_pfm, read_view_grid
from lftransfer.scenes import builtin_scene, load_scene, quick_scene, with_overrides
from lftransfer.sim.views import render_view_grid


def _scene():
    return with_overrides(quick_scene(load_scene(builtin_scene("fig6"))), view={"resolution": [160, 120]})


def test_01_the_sweep_finds_the_true_disparity(variant):
    grid, disparity, depth = render_view_grid(_scene(), n=5, baseline_m=0.002, shift_px=0, spp=4)
    assert grid.views.shape == (5, 5, 120, 160)
    assert grid.focus_m == np.inf and np.all(disparity[~np.isfinite(depth)] == 0)   # focused at infinity
    assert grid.disp_min < 0.0 and grid.disp_max > float(np.nanmax(disparity[np.isfinite(depth)]))
    shifted, moved, z = render_view_grid(_scene(), n=3, baseline_m=0.002, shift_px=1, spp=1)
    assert shifted.focus_m == pytest.approx(shifted.focal_px * 0.002)               # Z0 = f B / p
    np.testing.assert_allclose(moved, 0.002 * shifted.focal_px / z - 1.0, atol=1e-5)  # d = B f (1/z - 1/Z0)
    centre = grid.views[2, 2]
    textured = np.isfinite(depth) & (np.hypot(sobel(centre, 0), sobel(centre, 1)) > 0.1) & (centre > 0.05)
    assert textured.sum() > 300
    est = estimate_disparity(grid.views, disp_min=grid.disp_min, disp_max=grid.disp_max)
    err = np.abs(est.disparity - disparity)[textured]
    assert np.median(err) < 0.1
    wrong = estimate_disparity(grid.views[::-1, ::-1], disp_min=grid.disp_min, disp_max=grid.disp_max)
    assert np.median(np.abs(wrong.disparity - disparity)[textured]) > 5 * np.median(err)


def test_02_lft_sim_views_then_lft_depth(variant, tmp_path):
    from typer.testing import CliRunner

    from lftransfer.app.cli import app

    out = tmp_path / "views"
    runner = CliRunner()
    r = runner.invoke(app, ["sim", "views", "fig6", "--quick", "--views", "3", "--spp", "1", "--out", str(out)])
    assert r.exit_code == 0, r.output
    grid = read_view_grid(out)
    truth = read_pfm(out / "gt_disp_lowres.pfm")
    assert grid.views.shape[:2] == (3, 3) and truth.shape == grid.views.shape[2:]
    assert np.isfinite(truth).all()
    r = runner.invoke(app, ["depth", str(out), "--truth", str(out / "gt_disp_lowres.pfm"), "--out", str(out / "d")])
    assert r.exit_code == 0, r.output
    assert (out / "d" / "report.json").is_file()

"""Disparity of a light field of sub-aperture views (lftransfer.lightfield.disparity, lft depth): a known step edge
found where it is, the occlusion-aware cost against its control, the benchmark's scores as computed by hand, and
the PFM codec."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from lftransfer.lightfield.disparity import (disparity_to_depth, estimate_disparity, score_disparity,
                                             view_groups)
from lftransfer.lightfield.view_grid import (ViewGrid, ViewGridError, read_pfm, read_view_grid, two_layer_grid,
                                             write_pfm, write_view_grid)

D_BACK, D_FRONT = -0.5, 1.2            # pixels per view step: behind and in front of the focus plane


def _light_field(n: int = 5, size: int = 128, back_contrast: float = 1.0):
    """A grid of views of a textured square in front of a textured plane (``two_layer_grid``), and its truth."""
    grid, truth = two_layer_grid(n, size, front=D_FRONT, back=D_BACK, back_contrast=back_contrast)
    return grid.views, truth


def _bad_beyond(disparity: np.ndarray, truth: np.ndarray, px: float) -> int:
    """Pixels off by more than 0.07 farther than ``px`` from the true edge (15 px border left out)."""
    edge = cv2.Canny((truth > 0).astype(np.uint8) * 255, 50, 100) > 0
    dist = cv2.distanceTransform((~edge).astype(np.uint8), cv2.DIST_L2, 3)
    bad = np.abs(disparity - truth) > 0.07
    bad[:15], bad[-15:], bad[:, :15], bad[:, -15:] = False, False, False, False
    return int((bad & (dist > px)).sum())


def test_a_step_edge_lands_where_it_is():
    """On two textured layers the estimate is right everywhere but within two pixels of the occluding edge, and
    right within 0.02 px per step in the layers' middles."""
    views, truth = _light_field()
    est = estimate_disparity(views, disp_min=-1.5, disp_max=1.5, steps=32)
    assert _bad_beyond(est.disparity, truth, 2.0) == 0
    assert abs(np.median(est.disparity[truth > 0]) - D_FRONT) < 0.02
    assert abs(np.median(est.disparity[truth < 0]) - D_BACK) < 0.02
    assert score_disparity(est.disparity, truth)["badpix_0.07"] < 3.0
    assert est.confidence[truth > 0].mean() > 0.2 and est.disparity.dtype == np.float32


def test_the_occlusion_aware_cost_bleeds_less_than_the_mean_over_every_view():
    """Behind a strongly textured square a weakly textured plane lets the square's disparity bleed past its edge
    when every view's difference counts (the control); the best of the half-grids of views, which leave out the
    views the square hides the plane from, bleeds less than half as far (measured: 313 against 790 pixels
    beyond 2 px)."""
    views, truth = _light_field(back_contrast=0.1)
    aware = estimate_disparity(views, disp_min=-1.5, disp_max=1.5, steps=32)
    blind = estimate_disparity(views, disp_min=-1.5, disp_max=1.5, steps=32, occlusion_aware=False)
    assert _bad_beyond(aware.disparity, truth, 2.0) < 0.5 * _bad_beyond(blind.disparity, truth, 2.0)
    offsets = np.array([[s, t] for t in (-1, 0, 1) for s in (-1, 0, 1)])
    groups = view_groups(offsets)
    assert groups.shape == (4, 9) and groups.sum(axis=1).tolist() == [6, 6, 6, 6] and groups[:, 4].all()


def test_the_scores_are_the_benchmarks():
    """BadPix 0.07 and 100 x MSE over the pixels 15 or more from the border, as computed by hand; non-finite
    pixels left out; shapes checked."""
    truth = np.zeros((40, 50), np.float32)
    est = truth.copy()
    est[15:25, 15:35] = 0.1              # 200 of the 10 x 20 scored pixels, each 0.1 off
    est[20, 20] = np.nan
    s = score_disparity(est, truth)
    assert s["pixels"] == 199
    assert s["badpix_0.07"] == pytest.approx(100.0 * 199 / 199)
    assert s["mse_x100"] == pytest.approx(100.0 * 0.01, rel=1e-5)
    est[15:25, 15:35] = 0.05              # under the threshold: not bad, but in the squared error
    s = score_disparity(est, truth)
    assert s["badpix_0.07"] == 0.0 and s["mse_x100"] == pytest.approx(100.0 * 0.0025, rel=1e-5)
    with pytest.raises(ValueError, match="its ground truth"):
        score_disparity(est, truth[:-1])


def test_depth_follows_the_benchmarks_conversion():
    """Zero disparity is the focus distance, and d = B f (1/Z - 1/Z0): positive nearer."""
    z = disparity_to_depth(np.array([0.0, 1.0]), 0.01, 1000.0, 2.0)
    assert z[0] == pytest.approx(2.0) and z[1] == pytest.approx(1.0 / (1.0 / 10.0 + 0.5))


@settings(max_examples=40, deadline=None)
@given(arrays(np.float32, st.tuples(st.integers(1, 9), st.integers(1, 9)),
              elements=st.floats(width=32, allow_nan=True, allow_infinity=True)))
def test_pfm_round_trip(tmp_path_factory, image):
    path = tmp_path_factory.mktemp("pfm") / "map.pfm"
    write_pfm(path, image)
    np.testing.assert_array_equal(read_pfm(path), image)


def test_bad_files_are_named(tmp_path):
    (tmp_path / "x.pfm").write_bytes(b"PF\n2 2\n-1\n" + bytes(48))
    with pytest.raises(ViewGridError, match="x.pfm: not a one-channel PFM"):
        read_pfm(tmp_path / "x.pfm")
    (tmp_path / "y.pfm").write_bytes(b"Pf\n4 4\n-1\n" + bytes(8))
    with pytest.raises(ViewGridError, match="y.pfm: holds 8 bytes"):
        read_pfm(tmp_path / "y.pfm")
    with pytest.raises(ViewGridError, match="parameters.cfg: no such file"):
        read_view_grid(tmp_path)


def test_lft_depth_on_a_folder_scores_against_its_truth(tmp_path):
    """``lft depth DIR --truth FILE.pfm`` reads the benchmark's layout (written here from the two layers), writes
    the maps and their pictures, and scores the estimate; a missing view is named."""
    from typer.testing import CliRunner

    from lftransfer.app.cli import app

    views, truth = _light_field()
    grid = ViewGrid(views, baseline_m=0.01, focal_px=400.0, focus_m=1.0, disp_min=-1.5, disp_max=1.5)
    folder = write_view_grid(tmp_path / "lf", grid)
    write_pfm(tmp_path / "gt_disp_lowres.pfm", truth)
    assert read_view_grid(folder).views.shape == views.shape
    out = tmp_path / "out"
    result = CliRunner().invoke(app, ["depth", str(folder), "--out", str(out), "--steps", "32", "--truth",
                                      str(tmp_path / "gt_disp_lowres.pfm")])
    assert result.exit_code == 0, (result.output, result.exception)
    for name in ("disparity.pfm", "disparity.png", "depth.pfm", "depth.png", "confidence.png", "report.json"):
        assert (out / name).stat().st_size > 0, name
    import json

    report = json.loads((out / "report.json").read_text())
    assert report["scores"]["badpix_0.07"] < 3.0 and report["views"] == [5, 5, 128, 128]
    np.testing.assert_allclose(read_pfm(out / "disparity.pfm")[64, 64], D_FRONT, atol=0.05)
    (folder / "input_Cam007.png").unlink()
    missing = CliRunner().invoke(app, ["depth", str(folder), "--out", str(out)])
    assert missing.exit_code == 2 and "input_Cam007.png: no such file" in " ".join(missing.stderr.split())

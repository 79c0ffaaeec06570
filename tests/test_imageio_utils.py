"""The live page's display images (lftransfer.imageio_utils.to_preview) against the written images' sRGB
(to_display): within one code everywhere, equal almost everywhere, black for what cannot be shown."""

from __future__ import annotations

import numpy as np

from lftransfer.imageio_utils import PREVIEW_LEVELS, to_display, to_preview


def test_01_the_preview_is_within_one_code_of_the_written_image():
    rng = np.random.default_rng(0)
    x = (rng.random((64, 96, 3)) ** 3 * 1.3).astype(np.float32)          # darks, mids and clipped highlights
    for scale in (1.0, 0.37, 4.0):
        exact, preview = to_display(x, scale), to_preview(x, scale)
        assert preview.dtype == np.uint8 and preview.shape == exact.shape
        assert np.abs(exact.astype(int) - preview).max() <= 1
        assert np.mean(exact != preview) < 0.01
    # every code the curve can give: the table's own levels are exact
    levels = np.linspace(0.0, 1.0, PREVIEW_LEVELS, dtype=np.float64)[None, :, None]
    assert np.array_equal(to_preview(levels), to_display(levels))
    # negative control: a table of 256 linear levels is far off in the darks (the check can fail)
    coarse = to_display(np.round(x * 255) / 255)
    assert np.abs(coarse.astype(int) - to_display(x)).max() > 1


def test_02_negative_and_nan_show_black_and_the_input_is_untouched():
    x = np.array([[[np.nan, -1.0, 2.0], [0.5, np.inf, -np.inf]]], np.float32)
    kept = x.copy()
    out = to_preview(x)
    assert out.tolist() == [[[0, 0, 255], [to_display(np.array([0.5]))[0], 255, 0]]]
    assert np.array_equal(x, kept, equal_nan=True)

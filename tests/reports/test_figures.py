"""The reports' figure helpers: matplotlib on an Agg canvas, embedded as data URIs."""

from __future__ import annotations

import base64
import xml.etree.ElementTree as ET

import cv2
import numpy as np
import pytest
from matplotlib.backends.backend_agg import FigureCanvasAgg

from lftransfer.reports import figures


def _decode(uri: str) -> tuple[str, bytes]:
    head, b64 = uri.split(",", 1)
    return head, base64.b64decode(b64)


def test_01_svg_and_png_data_uris():
    x = np.linspace(0, 1, 11)
    fig = figures.line_plot([(x, x ** 2, "#d62728", "a & b")], [(x, x, "#1f77b4")], xlabel="x", ylabel="y < 1",
                            title="t", ylim=(0, 1))
    assert isinstance(fig.canvas, FigureCanvasAgg)
    svg = figures.data_uri(fig)
    head, data = _decode(svg)
    assert head == "data:image/svg+xml;base64"
    root = ET.fromstring(data)                                              # well-formed, text kept as text
    assert root.tag.endswith("svg") and b"a &amp; b" in data and b"y &lt; 1" in data
    assert b"<metadata" not in data and b"<dc:date" not in data             # no date, no creator
    head, data = _decode(figures.data_uri(fig, "png", dpi=50))
    png = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
    assert head == "data:image/png;base64" and png.shape[1] == round(50 * fig.get_figwidth())
    item = figures.embed(fig, "caption <x>")
    assert item["width"] == round(96 * fig.get_figwidth()) and item["alt"] == item["caption"] == "caption <x>"


def test_02_histogram_quiver_cell_map_image_panels():
    rng = np.random.default_rng(1)
    with pytest.raises(ValueError, match="no values"):
        figures.histogram(np.array([np.nan]), xlabel="k1", title="t")
    assert figures.histogram(rng.normal(size=50), xlabel="k1", title="t").axes[0].get_legend() is not None
    points = rng.uniform(0, 100, (20, 2))
    fig = figures.quiver(points, rng.normal(0, 0.01, (20, 2)), (80, 120), magnification=1000, key=0.01)
    assert fig.axes[0].get_ylim() == (79.5, -0.5)                           # image pixels, y down
    square = np.array([[0, 0], [10, 0], [10, 10], [0, 10]], float)
    cells = np.stack([square, square + 20])
    fig = figures.cell_map(cells, np.array([1.0, 2.0]), np.array([True, False]), (40, 40), label="k1")
    assert len(fig.axes) == 2                                               # the map and its colour bar
    fig, axes = figures.image_panels(rng.uniform(size=(30, 40)), (None, (5, 5, 15, 10)), cmap="viridis",
                                     label="v")
    assert len(axes) == 2 and axes[1].get_xlim() == (4.5, 14.5) and len(fig.axes) == 3
    assert figures.points_per_pixel(axes[0]) > 0
    with pytest.raises(ValueError, match="not an image"):
        figures.image_panels(np.zeros(3))


def test_03_nice_floor():
    assert [figures.nice_floor(v) for v in (0.0084, 1.0, 3.9, 7.2, 1000.0, 2000.0)] == \
        [0.005, 1.0, 2.0, 5.0, 1000.0, 2000.0]

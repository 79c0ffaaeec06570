"""Figures of the HTML reports: matplotlib figures (Agg canvas, no pyplot state) embedded as ``data:`` URIs.

Each plotting function returns a :class:`matplotlib.figure.Figure` in the reports' style; :func:`embed` turns it
into the dict that the templates' ``figure`` macro (``templates/macros.html``) shows. Plots are SVG, figures with
images in them PNG: nothing is fetched when a report is opened.

Example:
    >>> fig = histogram(np.random.default_rng(0).normal(size=100), xlabel="k1", title="k1 per lenslet")
    >>> embed(fig, "Histogram of k1.")["uri"].startswith("data:image/svg+xml;base64,")
    True
"""

from __future__ import annotations

import base64
import functools
import io
import math

import matplotlib
import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.collections import PolyCollection
from matplotlib.figure import Figure

__all__ = ["CHANNEL_COLOURS", "cell_map", "data_uri", "embed", "histogram", "image_panels", "image_row", "line_plot",
           "new_figure", "nice_floor", "points_per_pixel", "quiver"]

CHANNEL_COLOURS = ("#d62728", "#2ca02c", "#1f77b4")          # R, G, B
_STYLE = {"font.size": 9, "axes.titlesize": 10, "axes.titleweight": "bold", "axes.grid": True,
          "grid.color": "#e6e6e6", "axes.axisbelow": True, "axes.spines.top": False, "axes.spines.right": False,
          "legend.fontsize": 8, "legend.framealpha": 0.85, "svg.fonttype": "none", "svg.hashsalt": "lftransfer"}


def _styled(plot):
    """Run a plotting function in the reports' style (matplotlib reads rcParams as it makes the artists)."""
    @functools.wraps(plot)
    def wrapper(*args, **kwargs):
        with matplotlib.rc_context(_STYLE):
            return plot(*args, **kwargs)
    return wrapper


def new_figure(width: float = 4.8, height: float = 3.3) -> Figure:
    """An empty figure on an Agg canvas with constrained layout; ``width``, ``height`` in inches."""
    fig = Figure(figsize=(width, height), layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def data_uri(fig: Figure, fmt: str = "svg", dpi: int = 110) -> str:
    """A figure as a ``data:image/svg+xml;base64,...`` (text as text) or ``data:image/png;base64,...`` URI, with
    no date or creator in it; ``dpi``: of PNG and of images inside SVG."""
    buf = io.BytesIO()
    meta = dict.fromkeys(("Date", "Creator", "Format", "Type")) if fmt == "svg" else {"Software": None}
    with matplotlib.rc_context(_STYLE):
        fig.savefig(buf, format=fmt, dpi=dpi, metadata=meta)
    return f"data:image/{'svg+xml' if fmt == 'svg' else fmt};base64,{base64.b64encode(buf.getvalue()).decode()}"


def embed(fig: Figure, caption: str, alt: str = "", fmt: str = "svg") -> dict:
    """A figure for the templates' ``figure`` macro: ``{"uri", "width" (CSS px), "alt", "caption"}``."""
    return {"uri": data_uri(fig, fmt), "width": round(96 * fig.get_figwidth()), "alt": alt or caption,
            "caption": caption}


def nice_floor(v: float) -> float:
    """Largest 1, 2 or 5 times a power of ten not above ``v`` (> 0): scale bars and magnifications."""
    e = 10.0 ** math.floor(math.log10(v))
    return max(m * e for m in (1.0, 2.0, 5.0) if m * e <= v * (1 + 1e-9))


def points_per_pixel(ax) -> float:
    """One data unit along x (an image pixel) in points, the layout done: for markers that scale with images."""
    ax.figure.canvas.draw()
    return ax.bbox.width / ax.figure.dpi * 72.0 / abs(np.subtract(*ax.get_xlim()))


@_styled
def line_plot(lines=(), dots=(), *, xlabel: str, ylabel: str, title: str, xlim=None, ylim=None,
              dot_size: float = 2.5) -> Figure:
    """Lines, and dots over them, with a legend of the lines.

    Args:
        lines: (x, y, colour, label) per line; x, y (N,) arrays.
        dots: (x, y, colour) per set of dots (many dots are drawn as a raster).
        xlim, ylim: axis limits; None: the data's.
        dot_size: the dots' size, points.
    """
    fig = new_figure()
    ax = fig.add_subplot()
    for x, y, colour, label in lines:
        ax.plot(x, y, "-", lw=1.4, color=colour, label=label)
    for x, y, colour in dots:
        ax.plot(x, y, "o", ms=dot_size, color=colour, alpha=0.65, mec="#222" if dot_size > 3 else "none", mew=0.6,
                zorder=3, rasterized=np.size(x) > 200)
    ax.set(xlabel=xlabel, ylabel=ylabel, title=title, xlim=xlim, ylim=ylim)
    if lines:
        ax.legend(loc="upper left")
    return fig


@_styled
def histogram(values, *, xlabel: str, title: str, colour: str = "#4c72b0", ylabel: str = "count") -> Figure:
    """Histogram of the finite ``values`` ((N,); about sqrt(N) bins, 5 to 40) with the median marked.

    Raises:
        ValueError: no finite value.
    """
    v = np.asarray(values, np.float64).ravel()
    v = v[np.isfinite(v)]
    if v.size == 0:
        raise ValueError("no values to plot")
    fig = new_figure()
    ax = fig.add_subplot()
    ax.hist(v, bins=int(np.clip(round(math.sqrt(v.size)), 5, 40)), color=colour, edgecolor="white", lw=0.5)
    med = float(np.median(v))
    ax.axvline(med, color="#222", ls="--", lw=1, label=f"median {med:.4g}, N = {v.size}")
    ax.set(xlabel=xlabel, ylabel=ylabel, title=title)
    ax.locator_params(axis="x", nbins=6)
    ax.legend(loc="upper left")
    return fig


def _pixel_axes(ax, shape: tuple[int, int], box=None) -> None:
    """Axes in image pixels (centres at integers, y down, equal aspect) over the image of ``shape`` (H, W), or
    over ``box`` (x0, y0, x1, y1: half-open pixel ranges)."""
    x0, y0, x1, y1 = box or (0, 0, shape[1], shape[0])
    ax.set(xlim=(x0 - 0.5, x1 - 0.5), ylim=(y1 - 0.5, y0 - 0.5), aspect="equal", xlabel="x (px)", ylabel="y (px)")
    ax.grid(False)


@_styled
def quiver(points, vectors, image_shape: tuple[int, int], *, magnification: float, key: float, unit: str = "px",
           title: str = "", width: float = 5.6) -> Figure:
    """Arrows at points of an image, magnified, with a key arrow.

    Args:
        points: (N, 2) pixel positions (x, y); vectors: (N, 2) the arrows, in the same pixels.
        image_shape: (H, W) of the image.
        magnification: factor on the arrows' lengths.
        key: the key arrow's length before magnification; ``unit`` follows it.
    """
    p, v = np.asarray(points, np.float64).reshape(-1, 2), np.asarray(vectors, np.float64).reshape(-1, 2)
    fig = new_figure(width, width * image_shape[0] / image_shape[1] + 0.5)
    ax = fig.add_subplot()
    ax.plot(p[:, 0], p[:, 1], ".", ms=2.5, color="#555")
    q = ax.quiver(p[:, 0], p[:, 1], v[:, 0], v[:, 1], color="#c0392b", angles="xy", scale_units="xy",
                  scale=1.0 / magnification, width=0.003, headwidth=4, headlength=5, headaxislength=4.5)
    ax.quiverkey(q, 1.0, 1.03, key, f"{key:g} {unit}", labelpos="W", coordinates="axes")
    _pixel_axes(ax, image_shape)
    ax.set_title(title, loc="left")
    return fig


@_styled
def cell_map(cells, values, valid, image_shape: tuple[int, int], *, label: str, title: str = "",
             cmap: str = "viridis", width: float = 5.6) -> Figure:
    """Polygons in an image (e.g. lenslet cells) coloured by a value, with a colour bar.

    Args:
        cells: (K, V, 2) polygon vertices, pixels (x, y).
        values: (K,) the value per cell; where ``valid`` (K,) is False or the value not finite, grey.
        image_shape: (H, W) of the image.
        label: the colour bar's label.
    """
    v = np.ma.masked_invalid(np.where(np.asarray(valid, bool), np.asarray(values, np.float64), np.nan))
    fig = new_figure(width, (width - 1.9) * image_shape[0] / image_shape[1] + 0.7)
    ax = fig.add_subplot()
    coll = ax.add_collection(PolyCollection(np.asarray(cells, np.float64), array=v, edgecolors="white", lw=0.6,
                                            cmap=matplotlib.colormaps[cmap].with_extremes(bad="#bbbbbb")))
    fig.colorbar(coll, ax=ax, label=label, shrink=0.9)
    _pixel_axes(ax, image_shape)
    ax.set_title(title)
    return fig


@_styled
def image_panels(image, boxes=(None,), *, titles=(), cmap: str | None = None, lo=None, hi=None,
                 label: str | None = None, width: float = 6.4) -> tuple[Figure, list]:
    """An image in pixel coordinates, one panel per box side by side; the caller draws overlays on the axes.

    Args:
        image: (H, W) values (through ``cmap`` from ``lo`` to ``hi``; NaN grey) or (H, W, 3) RGB.
        boxes: per panel None (the whole image, smoothly resampled) or (x0, y0, x1, y1), half-open pixel ranges
            (a zoom, pixels drawn as blocks).
        titles: the panels' titles.
        label: the colour bar's label; None: no colour bar.
        width: the figure's width, inches.

    Returns:
        (figure, the panels' axes).
    """
    img = np.asarray(image)
    if img.ndim not in (2, 3) or min(img.shape[:2]) < 1:
        raise ValueError(f"not an image: shape {img.shape}")
    h, w = img.shape[:2]
    ratios = [(b[2] - b[0]) / max(b[3] - b[1], 1) for b in (b or (0, 0, w, h) for b in boxes)]
    fig = new_figure(width, (width - 0.9 - 0.9 * bool(label) - 0.5 * (len(boxes) - 1)) / sum(ratios) + 0.9)
    axes = list(fig.subplots(1, len(boxes), width_ratios=ratios, squeeze=False)[0])
    colours = matplotlib.colormaps[cmap].with_extremes(bad="#bbbbbb") if cmap else None
    for ax, box, title in zip(axes, boxes, [*titles, *[""] * len(boxes)]):
        shown = ax.imshow(img, cmap=colours, vmin=lo, vmax=hi, interpolation="nearest" if box else "antialiased")
        _pixel_axes(ax, (h, w), box)
        ax.set_title(title)
    if label:
        fig.colorbar(shown, ax=axes, label=label, shrink=0.9)
    return fig, axes


@_styled
def image_row(images, *, titles=(), cmap: str, lo: float, hi: float, label: str, width: float = 9.6) -> Figure:
    """Images of one quantity side by side on one colour scale, with one colour bar.

    Args:
        images: (H, W) arrays of the same shape (NaN grey).
        titles: the panels' titles.
        cmap: matplotlib colour map; ``lo``, ``hi``: its range.
        label: the colour bar's label (the quantity and its unit).
        width: the figure's width, inches.
    """
    images = [np.asarray(x, np.float64) for x in images]
    h, w = images[0].shape
    n = len(images)
    fig = new_figure(width, (width - 1.2 - 0.3 * (n - 1)) / n * h / w + 0.8)
    axes = list(fig.subplots(1, n, squeeze=False)[0])
    colours = matplotlib.colormaps[cmap].with_extremes(bad="#bbbbbb")
    for ax, img, title in zip(axes, images, [*titles, *[""] * n]):
        shown = ax.imshow(img, cmap=colours, vmin=lo, vmax=hi, interpolation="antialiased")
        _pixel_axes(ax, (h, w), None)
        ax.set_title(title)
    fig.colorbar(shown, ax=axes, label=label, shrink=0.9)
    return fig

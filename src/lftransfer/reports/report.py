"""Pictures and the JSON report of a run: the Fig. 4 bounce panel, light field images, composite."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import cv2
import numpy as np

from lftransfer.imageio_utils import to_display, write_exr, write_json, write_png


def display_scale(image: np.ndarray, percentile: float = 99.5, target: float = 0.9,
                  ceiling: float | None = None) -> float:
    """Factor that maps the image's ``percentile`` brightness to ``target`` of the display range.

    Args:
        image: (H, W, 3) linear radiance.
        ceiling: the percentile is taken over the lit pixels (some channel above 0) whose channels all stay below
            this radiance: emitters seen directly are left out (they would otherwise set the scale and leave the
            lit objects black; they saturate instead). None: over every pixel.
    """
    values = np.asarray(image)
    if ceiling is not None:
        peak = values.reshape(-1, values.shape[-1]).max(axis=1).reshape(values.shape[:-1])
        values = values[(peak > 0) & (peak < ceiling)]
    if values.size == 0:
        return 1.0
    level = float(np.percentile(values, percentile))
    return target / level if level > 0 else 1.0


def emitter_ceiling(scene) -> float | None:
    """Half the dimmest emitter's brightest channel (:func:`display_scale`'s ``ceiling``), None without emitters."""
    levels = [max(o.material.radiance) for o in scene.synthetic if o.material.type == "emitter"]
    return 0.5 * min(levels) if levels and min(levels) > 0 else None


def _label(tile: np.ndarray, text: str) -> np.ndarray:
    out = tile.copy()
    scale = max(0.4, tile.shape[1] / 700)
    thick = max(1, int(round(scale * 1.5)))
    (tw, th), base = cv2.getTextSize(text, cv2.FONT_HERSHEY_SIMPLEX, scale, thick)
    cv2.rectangle(out, (0, 0), (tw + 12, th + base + 12), (0, 0, 0), -1)
    cv2.putText(out, text, (6, th + 6), cv2.FONT_HERSHEY_SIMPLEX, scale, (255, 255, 255), thick, cv2.LINE_AA)
    return out


def _resize(image: np.ndarray, width: int) -> np.ndarray:
    h = int(round(image.shape[0] * width / image.shape[1]))
    return cv2.resize(image, (width, h), interpolation=cv2.INTER_AREA)


@dataclass(frozen=True)
class BounceLayer:
    """One bounce's real or synthetic layer as shown: at its own display scale, its gain written beside it.

    Attributes:
        side: "real" (R_n's view, ``Bounce.real_view``) or "synthetic" (S_n, ``Bounce.synthetic_view.rgb``).
        index: the bounce n (0 = direct light).
        scale: the display scale applied to the layer's radiance (:func:`display_scale`).
        gain: ``scale`` relative to the direct images' scale (1 for the direct images): how much brighter than the
            direct image the layer is shown.
        title: its label, e.g. "real bounce 1  x3.2".
        image: (H, W, 3) uint8 sRGB at the view camera's resolution, unlabelled.
    """

    side: str
    index: int
    scale: float
    gain: float
    title: str
    image: np.ndarray


def bounce_layers(result, composite_rgb: np.ndarray, *, ceiling: float | None = None) -> list[BounceLayer]:
    """The per-bounce layers of a bounce loop's run as :func:`bounce_panel` shows them.

    Args:
        result: :class:`lftransfer.transfer.bounce.TransferResult` (its bounces' ``real_view``: black where a
            bounce's view was not captured).
        composite_rgb: (H, W, 3) linear radiance of the final composite (sets the scale where both direct images
            are black, as in a scene lit only by synthetic emitters).
        ceiling: see :func:`display_scale` (emitters seen directly saturate).

    Returns:
        The real layers of bounces 0..N, then the synthetic ones; the direct ones at the direct scale (gain 1),
        each other one at its own scale.
    """
    base = _base_scale(result, composite_rgb, ceiling)
    layers = []
    for side in ("real", "synthetic"):
        for b in result.bounces:
            img = b.real_view if side == "real" else b.synthetic_view.rgb
            if img is None:
                img = np.zeros_like(result.real_view)
            img = np.clip(img, 0.0, None)
            s = base if b.index == 0 else display_scale(img, ceiling=ceiling)
            title = f"{side} {'direct' if b.index == 0 else f'bounce {b.index}'}  x{s / base:.3g}"
            layers.append(BounceLayer(side, b.index, s, s / base, title, to_display(img, s)))
    return layers


def bounce_panel(result, ground_truth: np.ndarray | None, composite_rgb: np.ndarray, *,
                 tile_width: int = 512, ceiling: float | None = None,
                 layers: list[BounceLayer] | None = None) -> np.ndarray:
    """The paper's Fig. 4 as one picture.

    Rows: real side (direct, bounce 1, ...), synthetic side (direct, bounce 1, ...), then the composite and the
    ground truth (where there is one: the simulated rig). Each tile is shown at its own display scale, written on
    it relative to the direct image. ``ceiling``: see :func:`display_scale` (emitters seen directly saturate).
    ``layers``: :func:`bounce_layers` of the same run where the caller has them already (else computed here).

    Returns:
        (H, W, 3) uint8 sRGB.
    """
    layers = layers if layers is not None else bounce_layers(result, composite_rgb, ceiling=ceiling)
    base = layers[0].scale
    rows = [np.concatenate([_label(_resize(x.image, tile_width), x.title) for x in layers if x.side == side], axis=1)
            for side in ("real", "synthetic")]
    last = [_label(_resize(to_display(composite_rgb, base), tile_width), "composite  x1")]
    if ground_truth is not None:
        last.append(_label(_resize(to_display(ground_truth, base), tile_width), "ground truth (path traced)  x1"))
        diff = np.abs(composite_rgb - ground_truth)
        gain = display_scale(diff, ceiling=ceiling) / base if np.any(diff > 0) else 1.0
        last.append(_label(_resize(to_display(diff, base * gain), tile_width),
                           f"|composite - ground truth|  x{gain:.3g}"))
    width = rows[0].shape[1]
    last_row = np.concatenate(last, axis=1)
    if last_row.shape[1] < width:
        last_row = np.pad(last_row, ((0, 0), (0, width - last_row.shape[1]), (0, 0)))
    rows.append(last_row[:, :width])
    return np.concatenate(rows, axis=0)


def device_image(codes: np.ndarray, bits: int, *, stretch: bool = False) -> np.ndarray:
    """A camera or projector image of device integers (H, W, 3) as 8-bit sRGB for viewing; ``stretch`` maps its
    99.9th percentile to 90 % (a dim capture), otherwise the full code range to the full display range."""
    x = np.asarray(codes, np.float64)[..., :3] / (2 ** bits - 1)
    if stretch:
        x = np.clip(x * 0.9 / max(float(np.percentile(x, 99.9)), 1e-9), 0.0, 1.0)
    return np.round(np.clip(x, 0.0, 1.0) ** (1 / 2.2) * 255).astype(np.uint8)


def live_panel(frame, ground_truth: np.ndarray | None, scale: float, *, camera_bits: int, projector_bits: int,
               tile_width: int = 384, names: Sequence[str] = ()) -> np.ndarray:
    """One frame of the live loop as a panel (the Fig. 4 panel of a live sequence).

    Top row: the LF camera's capture, the projector's image (the previous frame's synthetic light field) and the
    ground truth where there is one (with several light field interfaces, a row for each interface's LF camera and
    projector, named); bottom row: real view, synthetic view, composite, all at display ``scale``.

    Args:
        frame: :class:`lftransfer.transfer.live.LiveFrame`.
        ground_truth: (H, W, 3) path-traced image at the frame's time, or None.
        scale: display scale of the radiance images (kept over a sequence so that it does not flicker).
        names: the interfaces' names, with several (``frame.interfaces``); else unused.

    Returns:
        (H, W, 3) uint8 sRGB.
    """
    views = [(frame.real_view, "real view"), (frame.synthetic_view.rgb, "synthetic view"),
             (frame.composite, f"composite  t = {frame.time_s:.2f} s")]
    bottom = [_label(_resize(to_display(np.clip(img, 0, None), scale), tile_width), title) for img, title in views]
    h = bottom[0].shape[0]

    def fit(img: np.ndarray, title: str) -> np.ndarray:
        tile = cv2.resize(img, (tile_width, h), interpolation=cv2.INTER_AREA)
        return _label(tile, title)

    lit = [(light.captured_raw, light.projected_image) for light in frame.interfaces] or \
        [(frame.captured_raw, frame.projected_image)]
    named = [f"{name}: " for name in names] if frame.interfaces and len(names) == len(lit) else \
        [f"interface {k}: " for k in range(len(lit))] if frame.interfaces else [""]
    rows = []
    for k, ((raw, image), name) in enumerate(zip(lit, named)):
        top = [fit(device_image(raw, camera_bits, stretch=True), f"{name}LF camera (captured)"),
               fit(device_image(image, projector_bits), f"{name}projector (previous Ls)")]
        top.append(_label(_resize(to_display(ground_truth, scale), tile_width), "ground truth (path traced)")
                   if ground_truth is not None and k == 0 else np.zeros_like(bottom[0]))
        rows.append(np.concatenate(top, axis=1))
    return np.concatenate([*rows, np.concatenate(bottom, axis=1)], axis=0)


def _base_scale(result, composite_rgb: np.ndarray, ceiling: float | None) -> float:
    """The display scale of a run's direct images (the dimmer of the real and synthetic ones; the composite's
    where both are black, as in a scene lit only by synthetic emitters)."""
    direct = [img for img in (result.bounces[0].real_view, result.bounces[0].synthetic_view.rgb)
              if img is not None and np.any(img > 0)]
    if not direct:
        return display_scale(composite_rgb, ceiling=ceiling)
    return min(display_scale(img, ceiling=ceiling) for img in direct)


def _luminance(rgb: np.ndarray) -> np.ndarray:
    """(H, W) Rec. 709 luminance of a linear (H, W, 3) image."""
    return np.asarray(rgb, np.float64)[..., :3] @ np.array([0.2126, 0.7152, 0.0722])


def error_figure(composite_rgb: np.ndarray, ground_truth: np.ndarray):
    """``error.png``: |composite - ground truth| (luminance, W m^-2 sr^-1) on a scale to its 99.5th percentile,
    beside the ground truth's own brightness for where it is."""
    from lftransfer.reports.figures import image_row

    diff = np.abs(_luminance(composite_rgb) - _luminance(ground_truth))
    hi = max(float(np.percentile(diff, 99.5)), 1e-12)
    return image_row([diff], titles=[f"|composite - ground truth|  (mean {diff.mean():.3g}, 99.5 % below "
                                     f"{hi:.3g})"], cmap="magma", lo=0.0, hi=hi,
                     label="luminance difference, W m$^{-2}$ sr$^{-1}$", width=6.4)


def cross_term_figure(transfer: np.ndarray, truth: np.ndarray):
    """``cross_term.png``: what the real and synthetic objects add to each other's appearance, the transfer's
    (composite after the exchange - composite without it) beside the truth's (the union - the objects rendered
    alone, both seeds' mean) and their difference, one signed scale (W m^-2 sr^-1; light added red, light taken
    away, a shadow, blue)."""
    from lftransfer.reports.figures import image_row

    c_lft, c_gt = _luminance(transfer), _luminance(truth)
    hi = max(float(np.percentile(np.abs(c_gt), 99.5)), float(np.percentile(np.abs(c_lft), 99.5)), 1e-12)
    return image_row([c_lft, c_gt, c_lft - c_gt], titles=["cross term: the transfer", "cross term: the truth",
                                                          "transfer - truth"],
                     cmap="RdBu_r", lo=-hi, hi=hi, label="luminance, W m$^{-2}$ sr$^{-1}$")


def write_error_pictures(folder: Path, suffix: str, composite_rgb: np.ndarray, ground_truth: np.ndarray,
                         transfer_cross: np.ndarray | None, truth_cross: np.ndarray | None) -> list[Path]:
    """``error{suffix}.png`` (:func:`error_figure`) and, given both cross terms (H, W, 3), ``cross_term{suffix}.png``
    (:func:`cross_term_figure`) in ``folder``: a run's, or a sequence's verified frame's (``suffix`` "_0004")."""
    from lftransfer.imageio_utils import write_figure

    files = [write_figure(folder / f"error{suffix}.png", error_figure(composite_rgb, ground_truth))]
    if transfer_cross is not None and truth_cross is not None:
        files.append(write_figure(folder / f"cross_term{suffix}.png", cross_term_figure(transfer_cross, truth_cross)))
    return files


def write_outputs(out: str | Path, result, ground_truth: np.ndarray | None, composite_rgb: np.ndarray, report: dict,
                  captured_raw: np.ndarray | None = None, camera_bits: int = 12,
                  ceiling: float | None = None, cross_truth: np.ndarray | None = None) -> list[Path]:
    """Write every output file of a run into ``out`` (the ground truth's only where there is one, with the
    pictures of the error: ``error.png``, and ``cross_term.png`` given the truth's cross term ``cross_truth``,
    (H, W, 3)); returns their paths. ``ceiling``: see :func:`display_scale`."""
    out = Path(out)
    scale = _base_scale(result, composite_rgb, ceiling)
    files = [
        write_png(out / "composite.png", to_display(composite_rgb, scale)),
        write_exr(out / "composite.exr", composite_rgb),
    ]
    if ground_truth is not None:
        files += [write_png(out / "ground_truth.png", to_display(ground_truth, scale)),
                  write_exr(out / "ground_truth.exr", ground_truth.astype(np.float32))]
        files += write_error_pictures(out, "", composite_rgb, ground_truth,
                                      None if cross_truth is None else composite_rgb - result.composite_direct(),
                                      cross_truth)
    files += [
        write_png(out / "bounces.png", bounce_panel(result, ground_truth, composite_rgb, ceiling=ceiling)),
        write_png(out / "projected_lf.png", _eight_bits(result.projected_image)),
    ]
    names = (report.get("interfaces") or {}).get("names")
    if names and len(getattr(result, "projected_images", ())) == len(names):
        files.append(write_png(out / "interfaces.png", interfaces_panel(
            result.projected_images, names, getattr(result, "captured_raws", ()), camera_bits)))
    if captured_raw is not None:
        files.append(write_png(out / "captured_lf.png", device_image(captured_raw, camera_bits, stretch=True)))
    if getattr(result, "probe", None) is not None:
        files += [write_png(out / "probe.png", probe_panel(result.probe)),
                  write_exr(out / "probe.exr", result.probe.radiance)]
    files.append(write_json(out / "report.json", report))
    return files


def _eight_bits(image: np.ndarray) -> np.ndarray:
    """A projector image (uint8, or uint16 of a deeper projector) as 8-bit RGB."""
    return image[..., :3].astype(np.uint8) if image.dtype == np.uint8 else (image >> 8).astype(np.uint8)


def interfaces_panel(images, names, captured=(), camera_bits: int = 12,
                     titles: tuple[str, str] = ("its LF camera, direct frame", "its projector, final frame")
                     ) -> np.ndarray:
    """(H', W', 3) uint8: a row per interface, named: the light field its LF camera captured in the direct frame
    (``captured``, device integers, stretched; left out where not given) beside the one its projector sends the real
    objects in the final frame (``images``): what each array takes in and gives back (docs/interfaces.md). A live
    frame's (the page) says so in ``titles`` (the capture's, the projector's)."""
    rows = []
    for i, (image, name) in enumerate(zip(images, names)):
        shown = _eight_bits(np.asarray(image))
        tiles = [_label(shown, f"{name}: {titles[1]}")]
        if i < len(captured):
            taken = _resize(device_image(captured[i], camera_bits, stretch=True), shown.shape[1])
            tiles.insert(0, _label(taken, f"{name}: {titles[0]}"))
        height = max(t.shape[0] for t in tiles)
        rows.append(np.concatenate([np.pad(t, ((0, height - t.shape[0]), (0, 0), (0, 0))) for t in tiles], axis=1))
    width = max(r.shape[1] for r in rows)
    return np.concatenate([r if r.shape[1] == width else _resize(r, width) for r in rows], axis=0)


def probe_panel(probe) -> np.ndarray:
    """(H', W, 3) uint8: the light probe's photograph (top) over the map it gave, as wide as the photograph
    (bottom; its unmeasured directions, filled, drawn at half brightness), both at the sky's display scale (the
    sun saturates)."""
    photo = np.asarray(probe.photo, np.float32)
    w = photo.shape[1]
    room = cv2.resize(probe.radiance, (w, w // 2), interpolation=cv2.INTER_LINEAR)
    measured = cv2.resize(probe.measured.valid.astype(np.float32), (w, w // 2), interpolation=cv2.INTER_NEAREST)
    room = room * (0.5 + 0.5 * measured)[..., None]
    scale = display_scale(room, percentile=95.0)
    return np.concatenate([to_display(photo, scale), to_display(room, scale)], axis=0)

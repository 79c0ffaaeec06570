"""An HTML report of a rig calibration, with pictures (for the people who check a calibration by eye).

:func:`write_calibration_report` writes one self-contained file, ``calibration_report.html``: the Jinja template
``templates/calibration_report.html`` (autoescaped) lays out and explains what this module computes (numbers, tables
as lists of rows, matplotlib figures from :mod:`lftransfer.reports.figures` as ``data:`` URIs). Its sections follow the
calibration's steps (:mod:`lftransfer.calibration.rig`): a summary of the calibration file's key numbers and, if
given, the errors against a simulated rig's hidden truth
(:func:`lftransfer.sim.calibration_errors.calibration_errors`) with the
project's targets (:mod:`lftransfer.calibration.targets`) marked pass or fail; the lenslet centres (collimated image,
a full-resolution crop, the lattice fit's residuals as arrows); the lenslet distortion (histograms of k1 and k2, a map
of k1); the projector mapping (homography); the radiometry (responses, cross-talk, black level, vignetting,
brightness); the global pose (the view camera's photographs, the decoded fringe points and their reprojections).

A calibration read from a file (:func:`lftransfer.calibration.rig.load_calibration`) has no lattice, distortion or
projector fit and no diagnostics: those parts say so, and what its model holds is shown. A missing or malformed
diagnostic leaves its picture out (a malformed calibration its section); it never stops the report.
"""

from __future__ import annotations

import math
from pathlib import Path

import matplotlib
import numpy as np
from matplotlib.colors import to_hex
from matplotlib.patches import Rectangle

from lftransfer.reports import figures
from lftransfer.reports.figures import CHANNEL_COLOURS, embed
from lftransfer.reports.templating import _num, _vec, environment
from lftransfer.calibration.targets import TARGETS as CALIBRATION_TARGETS
from lftransfer.imageio_utils import to_display, write_text
from lftransfer.optics.geometry import apply_homography

__all__ = ["REPORT_NAME", "SECTIONS", "TARGETS", "render_calibration_report", "write_calibration_report"]

REPORT_NAME = "calibration_report.html"
SECTIONS = ("Summary", "Lenslet centres", "Lenslet distortion", "Projector mapping", "Radiometry", "Global pose")
NOT_AVAILABLE = "not available (loaded from file)"

# the project's targets against the hidden truth (calibration/targets.py): key of calibration_errors -> target
TARGETS = {t.key: t for t in CALIBRATION_TARGETS}

# key of calibration_errors -> (what it is, unit, display factor)
_ERROR_ROWS = {
    "lenslet_centre_rms_px": ("lenslet centres, RMS", "LF camera px", 1.0),
    "lenslet_centre_max_px": ("lenslet centres, max", "LF camera px", 1.0),
    "lenslets_found": ("lenslets found", "", 1.0),
    "lenslet_assignment_agreement": ("camera pixels assigned to the right lenslet", "%", 100.0),
    "ray_direction_rms_deg": ("ray direction per camera pixel, RMS", "deg", 1.0),
    "projector_mapping_rms_px": ("projector mapping, RMS", "projector px", 1.0),
    "pose_position_rms_mm": ("pose: lenslet positions in the world, RMS", "mm", 1.0),
    "pose_position_max_mm": ("pose: lenslet positions in the world, max", "mm", 1.0),
    "pose_rotation_deg": ("pose: array orientation", "deg", 1.0),
    "pitch_rel_error": ("pitch, relative", "%", 100.0),
    "distortion_k1_rms": ("distortion k1, RMS", "", 1.0),
    "camera_response_error": ("camera response, max", "% of full scale", 100.0),
    "projector_response_error": ("projector response, max", "% of full scale", 100.0),
    "projector_mixing_rel_error": ("projector mixing (brightness x cross-talk), max", "% of max", 100.0),
    "black_level_error": ("black level, max", "% of max radiance", 100.0),
    "exposure_rel_error": ("camera exposure, relative", "%", 100.0),
    "camera_gain_rel_rms": ("camera gain (exposure x vignetting), RMS relative", "%", 100.0),
    "light_position_error_mm": ("point light position", "mm", 1.0),
    "relative_position_rms_mm": ("lenslet positions in the first interface's array frame, RMS", "mm", 1.0),
    "relative_position_max_mm": ("lenslet positions in the first interface's array frame, max", "mm", 1.0),
    "relative_rotation_deg": ("orientation against the first interface's array", "deg", 1.0),
}

# brightness measurements: (radiometry diagnostics "rad" or exposure diagnostics "exp", key, what, format, unit)
_BRIGHTNESS = (
    ("rad", "board_centre_m", "board centre (model frame)", ".3f", "m"),
    ("rad", "board_pixels", "board pixels compared", ".10g", ""),
    ("rad", "board_measured_mean", "board radiance measured by the view camera (R, G, B)", ".4g", "W / (m^2 sr)"),
    ("rad", "board_ratio_per_channel", "measured / rendered at max_radiance 1 (R, G, B)", ".5g", ""),
    ("rad", "exposure_times_diffuser", "diffuser transmission x camera exposure", ".5g", ""),
    ("exp", "view_radiance", "exposure board: view camera radiance (R, G, B)", ".4g", "W / (m^2 sr)"),
    ("exp", "lf_radiance", "exposure board: LF camera radiance before correction (R, G, B)", ".4g", "W / (m^2 sr)"),
    ("exp", "rays", "exposure board: LF camera rays used", ".10g", ""),
    ("exp", "rays_left_out", "exposure board: LF camera rays not used (from behind or grazing)", ".10g", ""),
)
# response plots: device -> (x label, y label, what the dots and lines are)
_RESPONSES = {"camera": ("relative exposure x linear signal", "normalised camera code",
                         "dots: pixels of the exposure bracket; lines: code = signal^(1/gamma)"),
              "projector": ("normalised projector code", "normalised drive (light)",
                            "dots: measured, black level subtracted; lines: drive = code^gamma")}
_CHANNELS = ("R", "G", "B")
_CYAN, _ORANGE = "#28dcff", "#ff9620"
# what a malformed calibration or diagnostic raises while its part is computed or drawn
_SKIPPED = (KeyError, IndexError, TypeError, ValueError, AttributeError, ZeroDivisionError, np.linalg.LinAlgError)


def write_calibration_report(path, calibration, errors=None) -> Path:
    """Write the calibration report as one self-contained HTML file, atomically.

    Args:
        path: a folder (the file is ``calibration_report.html`` in it) or a file name ending in ``.html``;
            missing folders are created.
        calibration: :class:`lftransfer.calibration.rig.Calibration`.
        errors: errors against a simulated rig's hidden truth
        (:class:`lftransfer.sim.calibration_errors.CalibrationErrors`,
            or its ``to_json()``), shown with the project's targets; None to leave that table out.

    Returns:
        Path of the written file.
    """
    path = Path(path)
    if path.suffix.lower() not in (".html", ".htm"):
        path = path / REPORT_NAME
    return write_text(path, render_calibration_report(calibration, errors))


def render_calibration_report(calibration, errors=None) -> str:
    """The calibration report as an HTML document (see :func:`write_calibration_report`); a calibration of several
    light field interfaces (:class:`~lftransfer.calibration.interfaces.InterfacesCalibration`) shows each in turn,
    with its errors (``errors["interfaces"][name]``).

    Returns:
        the document's text.
    """
    errors = errors.to_json() if hasattr(errors, "to_json") else errors
    names = getattr(calibration, "names", None)
    if names is None:
        parts = [_part(calibration, errors)]
    else:
        each = (errors or {}).get("interfaces", {})
        parts = [_part(c, each.get(n), name=n, prefix=f"i{i}-" if i else "",
                       note=" (the world's frame; the point lights)" if i == 0 else "")
                 for i, (n, c) in enumerate(zip(names, calibration.interfaces))]
    first = calibration.model
    a, cam, prj = first.array, first.camera.device, first.projector.device
    count = "" if names is None else f"{len(names)} interfaces ({', '.join(names)}), each a "
    return environment().get_template("calibration_report.html").render(
        title="Light field transfer rig: calibration report", sections=SECTIONS, not_available=NOT_AVAILABLE,
        subtitle=f"{count}{a.rows} x {a.cols} {a.lattice} lens array; LF camera {cam.width} x {cam.height} px, "
                 f"projector {prj.width} x {prj.height} px", parts=parts)


def _part(cal, errors: dict | None, *, name: str = "", prefix: str = "", note: str = "") -> dict:
    """One interface's sections of the report."""
    diag = cal.diagnostics if isinstance(cal.diagnostics, dict) else {}
    return dict(name=name, prefix=prefix, note=note, summary=_attempt(_summary, cal, errors),
                lenslets=_attempt(_lenslets, cal, diag), distortion=_attempt(_distortion, cal),
                projector=_attempt(_projector, cal), radiometry=_attempt(_radiometry, cal, diag),
                pose=_attempt(_pose, cal, diag))


# ---- sections: each returns the values its part of the template shows ------------------------------------------
def _summary(cal, errors: dict | None) -> dict:
    """Key numbers of the calibration file, rows (step, quantity, value, unit); the errors against the truth."""
    data = cal.to_json()
    la, pose, rad = data["lens_array"], data["pose"], data["radiometry"]
    rows = [("lens array", "lattice", f"{la['lattice']}, {la['rows']} x {la['cols']} lenslets", ""),
            ("lens array", "pitch", _num(la["pitch_m"] * 1e3, ".4f"), "mm"),
            ("lens array", "focal length", _num(la["focal_length_m"] * 1e3, ".4f"), "mm"),
            ("lens array", "in-plane rotation", _num(la["rotation_deg"], ".4f"), "deg"),
            ("lens array", "offset (x, y)", _vec(np.asarray(la["offset_m"]) * 1e3, ".3f"), "mm"),
            ("lens array", "tilt (about x, about y)", _vec(la["tilt_deg"], ".4f"), "deg"),
            ("lens array", "scale (true / nominal pitch)", _num(pose["scale"], ".6f"), "")]
    if "lenslet_centres" in data:
        lc, lat = data["lenslet_centres"], cal.lattice
        rows += [("lenslet centres", "lenslets found", f"{len(lc['centres_px'])} ({lat.rejected} dropped)", ""),
                 ("lenslet centres", "pitch in the LF camera", _num(lc["pitch_px"], ".3f"), "px"),
                 ("lenslet centres", "rotation in the LF camera", _num(lc["rotation_deg"], ".3f"), "deg"),
                 ("lenslet centres", "lattice fit residual, RMS", _num(lc["rms_px"], ".4f"), "px"),
                 ("lenslet centres", "lattice fit residual, max", _num(lat.max_residual_px, ".4f"), "px"),
                 ("lenslet centres", "spot blur sigma", _num(lat.spot_sigma_px, ".2f"), "px")]
    else:
        rows.append(("lenslet centres", "lattice fit", NOT_AVAILABLE, ""))
    if "distortion" in data:
        rows += [("lenslet distortion", "collimator mount angle", _num(data["distortion"]["mount_angle_deg"], ".4f"),
                  "deg"),
                 ("lenslet distortion", "fit residual, RMS", _num(data["distortion"]["rms"], ".3g"), "focal lengths")]
    else:
        rows.append(("lenslet distortion", "fit", NOT_AVAILABLE, ""))
    k1 = np.asarray(cal.model.camera.device.distortion)[:, 0]
    rows.append(("lenslet distortion", "k1, median (min .. max)",
                 f"{np.median(k1):.4f} ({k1.min():.4f} .. {k1.max():.4f})", ""))
    if "projector_mapping" in data:
        pm = data["projector_mapping"]
        rows += [("projector mapping", "residual, RMS", _num(pm["rms_px"], ".3f"), "projector px"),
                 ("projector mapping", "camera pixels used", str(pm["pixels"]), "")]
    else:
        rows.append(("projector mapping", "Gray-code fit", NOT_AVAILABLE, ""))
    lights = cal.lights
    lf, pj = data["lf_camera"], data["projector"]
    rows += [("global pose", "projected fringe points, reprojection RMS", _num(pose["rms_px"], ".3f"), "view px"),
             ("global pose", "printed chessboard (solvePnP), RMS", _num(pose["pnp_rms_px"], ".3f"), "view px"),
             ("global pose", "3-D residual of the pose fit, RMS", _num(pose["residual_mm"], ".3f"), "mm"),
             ("radiometry", "camera gamma (R, G, B)", _vec(rad["camera_gamma"], ".4f"), ""),
             ("radiometry", "projector gamma (R, G, B)", _vec(rad["projector_gamma"], ".4f"), ""),
             ("radiometry", "camera exposure", _num(rad["camera_exposure"], ".5g"), "sr m^2 / W"),
             ("radiometry", "projector max_radiance", _num(rad["max_radiance"], ".5g"), "W / (m^2 sr)"),
             ("radiometry", "black level (R, G, B)", _vec(rad["black_level"], ".5f"), "of max_radiance"),
             *([("point light", "position", "not measured: the scene file's position stands", "")] if not lights
               else [row for i, light in enumerate(lights) for row in _light_rows(
                   "point light" if len(lights) == 1 else f"point light {i + 1}", light)]),
             ("devices", "LF camera", f"{lf['width']} x {lf['height']}, {lf['bits']} bit", "px"),
             ("devices", "projector", f"{pj['width']} x {pj['height']}, {pj['bits']} bit", "px")]
    return {"rows": rows, "errors": _error_rows(errors) if errors else None}


def _light_rows(name: str, light) -> list[tuple[str, str, str, str]]:
    """The table's rows of one measured point light."""
    return [(name, "position (x, y, z)", _vec(light.position * 1e3, ".2f"), "mm"),
            (name, "moved from the scene file's position", _num(light.shift_mm, ".2f"), "mm"),
            (name, "fit residual, RMS (relative)", _num(100 * light.residual_rms, ".3f"), "%"),
            (name, "standard error from the residuals (x, y, z)", _vec(light.std_mm, ".3f"), "mm"),
            (name, "boards, view pixels", f"{light.boards}, {light.pixels}", "")]


def _error_rows(errors: dict) -> list[dict]:
    """Errors against the hidden truth: known keys in their order, then the others; non-numbers left out.

    Returns:
        rows ``{"label", "value", "unit", "target" ("" without one), "verdict" ("pass", "fail" or "")}``.
    """
    rows = []
    for key in [*(k for k in _ERROR_ROWS if k in errors), *(k for k in errors if k not in _ERROR_ROWS)]:
        label, unit, factor = _ERROR_ROWS.get(key, (key, "", 1.0))
        value, target = errors[key], TARGETS.get(key)
        if not isinstance(value, (int, float, np.integer, np.floating)) or isinstance(value, bool):
            continue
        rows.append({"label": label, "unit": unit,
                     "value": str(int(value)) if isinstance(value, (int, np.integer)) else f"{value * factor:.5g}",
                     "target": f"≤ {target.bound * factor:.4g}" if target else "",
                     "verdict": ("pass" if target.met(value) else "fail") if target else ""})
    return rows


def _lenslets(cal, diag: dict) -> dict:
    """The lattice fit, and its pictures: collimated image with centres and a crop; the residual arrows."""
    lat = cal.lattice
    if lat is None:
        return {"fit": None}
    raw = diag.get("collimated")
    pictures = [{"note": f"Collimated image {NOT_AVAILABLE}."} if raw is None else
                _attempt(_lenslet_picture, raw, lat, cal.model.camera.levels, what="collimated image"),
                _attempt(_lenslet_quiver, lat, what="residual plot")]
    return {"fit": lat, "distorted": bool(np.any(lat.distortion)), "pictures": pictures}


def _distortion(cal) -> dict:
    """Per-lenslet (k1, k2): the fit's numbers, histograms and the k1 map."""
    fit = cal.distortion
    coeffs = np.asarray(cal.model.camera.device.distortion if fit is None else fit.coefficients, np.float64)
    used = np.ones(len(coeffs), bool) if fit is None else np.asarray(fit.spots) >= 4
    pictures = [_attempt(lambda i=i: embed(
        figures.histogram(coeffs[used, i], xlabel=f"k{i + 1}", ylabel="lenslets", title=f"k{i + 1} per lenslet",
                          colour=("#4c72b0", "#dd8452")[i]), f"Histogram of k{i + 1} over the lenslets."),
        what=f"k{i + 1}") for i in range(2)]
    pictures.append(_attempt(_distortion_map, cal, coeffs[:, 0], used, what="k1 map"))
    return {"fit": fit, "mount_angle_deg": None if fit is None else math.degrees(fit.mount_angle),
            "used": int(used.sum()), "count": len(used), "pictures": pictures}


def _projector(cal) -> dict:
    """The camera-to-projector homography (the fit's, or the model's) and its scale at the image centre."""
    fit, cam = cal.projector_fit, cal.model.camera.device
    if fit is not None:
        H = np.asarray(fit.homography, np.float64)
    else:
        H = cal.model.projector.device.homography @ np.linalg.inv(cam.homography)
        H = H / H[2, 2]
    p = np.array([cam.width, cam.height]) / 2 - 0.5                      # the camera image's centre
    w = H[2, :2] @ p + H[2, 2]
    q = (H[:2, :2] @ p + H[:2, 2]) / w
    jacobian = (H[:2, :2] - q[:, None] * H[2:3, :2]) / w
    return {"fit": fit, "matrix": [[f"{v:.6g}" for v in row] for row in H],
            "scale": math.sqrt(abs(np.linalg.det(jacobian)))}


def _radiometry(cal, diag: dict) -> dict:
    """Response plots, cross-talk as a heat table, black level, brightness rows, vignetting map."""
    rad = cal.radiometry
    rd = rad.diagnostics if isinstance(rad.diagnostics, dict) else {}
    m = np.asarray(rad.cross_talk, np.float64)
    t = np.abs(m) / (np.abs(m).max() or 1.0)
    blues = matplotlib.colormaps["Blues"]
    cross_talk = [(f"light {c}", [(f"{v:.4f}", to_hex(blues(0.95 * s)), "white" if s > 0.5 else "#111")
                                  for v, s in zip(row, srow)]) for c, row, srow in zip(_CHANNELS, m, t)]
    return {"rad": rad, "channels": _CHANNELS, "cross_talk": cross_talk,
            "black_level": [("black level", *(f"{v:.5f}" for v in rad.black_level))],
            "brightness": _brightness_rows(rad, rd, diag.get("exposure")),
            "pictures": [_attempt(_response_plot, rad, rd, "camera", what="camera response"),
                         _attempt(_response_plot, rad, rd, "projector", what="projector response"),
                         _attempt(_vignetting_figure, rad, rd, what="vignetting map")]}


def _pose(cal, diag: dict) -> dict:
    """The pose's numbers, the board photographs with the decoded points, a table of the points' residuals."""
    pose = cal.pose
    pd = diag.get("pose") if isinstance(diag.get("pose"), dict) else None
    pictures = []
    if pd is None:
        pictures.append({"note": f"Board photographs {NOT_AVAILABLE}."})
    else:
        images = pd.get("images") if isinstance(pd.get("images"), dict) else {}
        if images.get("flood") is not None:
            pictures.append(_attempt(_flood_figure, images["flood"], what="flood"))
        if pd.get("normalised") is not None:
            pictures.append(_attempt(_pose_corners_figure, pose, pd, what="corners"))
    corners = np.asarray(pose.corners_px, np.float64).reshape(-1, 2)
    reproj = np.asarray(pose.reprojected, np.float64).reshape(-1, 2)
    rows = None
    if len(corners) and len(corners) == len(reproj):
        rows = [(str(i), f"{c[0]:.3f}", f"{c[1]:.3f}", f"{p[0]:.3f}", f"{p[1]:.3f}", f"{p[0] - c[0]:+.3f}",
                 f"{p[1] - c[1]:+.3f}", f"{np.hypot(*(p - c)):.3f}") for i, (c, p) in enumerate(zip(corners, reproj))]
    return {"pose": pose, "rotation_deg": math.degrees(pose.rotation), "tilt_deg": np.degrees(pose.tilt),
            "offset_mm": np.asarray(pose.offset) * 1e3, "pictures": pictures, "residuals": rows}


def _brightness_rows(rad, rd: dict, exposure) -> list[tuple[str, str, str]]:
    """Rows (measurement, value, unit) of the brightness and exposure table, from the measurements present."""
    sources = {"rad": rd, "exp": exposure if isinstance(exposure, dict) else {}}
    rows = [("projector max_radiance", _num(rad.max_radiance, ".5g"), "W / (m^2 sr)"),
            ("camera exposure", _num(rad.camera_exposure, ".5g"), "sr m^2 / W")]
    for source, key, what, fmt, unit in _BRIGHTNESS:
        if key in sources[source]:
            value = sources[source][key]
            rows.append((what, _vec(value, fmt) if np.ndim(value) else _num(value, fmt), unit))
    captures = rd.get("captures")
    if isinstance(captures, dict):
        rows.append(("captures (focal plane, board)",
                     f"{captures.get('focal_plane', '?')}, {captures.get('board', '?')}", ""))
    return rows


# ---- figures ----------------------------------------------------------------------------------------------------
def _lenslet_picture(raw, lat, levels: int) -> dict:
    """The collimated image with the detected centres and the lattice's nodes, and a full-resolution crop."""
    img = _tone_map_codes(raw, levels)
    h, w = img.shape
    k = int(np.argmin(lat.centres.sum(axis=1)))                       # the lenslet nearest the top-left corner
    c = lat.centres[k]
    half = int(np.clip(math.ceil(5 * lat.spot_sigma_px), 6, max(6, 0.45 * lat.pitch_px)))
    x0, y0 = max(0, int(round(c[0])) - half), max(0, int(round(c[1])) - half)
    box = (x0, y0, min(w, x0 + 2 * half + 1), min(h, y0 + 2 * half + 1))
    row, col = lat.indices[k]
    fig, (whole, crop) = figures.image_panels(img, (None, box), cmap="gray", lo=0.0, hi=1.0, width=9.6,
                                              titles=("collimated image", f"lenslet ({row}, {col}), full resolution"))
    nodes = lat.predicted(lat.indices)
    for ax, size in ((whole, float(np.clip(0.4 * lat.pitch_px * figures.points_per_pixel(whole), 3, 14))),
                     (crop, 18.0)):
        ax.plot(nodes[:, 0], nodes[:, 1], "o", ms=size, mfc="none", mec=_CYAN, mew=1.0)
        ax.plot(lat.centres[:, 0], lat.centres[:, 1], "+", ms=size, color=_ORANGE, mew=1.0)
    whole.add_patch(Rectangle((box[0] - 0.5, box[1] - 0.5), box[2] - box[0], box[3] - box[1], fill=False, ec="y"))
    crop.set_xticks(np.arange(box[0], box[2] + 1) - 0.5, minor=True)
    crop.set_yticks(np.arange(box[1], box[3] + 1) - 0.5, minor=True)
    crop.grid(which="minor", color="#555", lw=0.4)
    r = c - nodes[k]
    return embed(fig, f"Collimated image ({w} x {h} px; grey, black point just above the background noise, gamma "
                      f"0.5): detected spot centres as orange crosses, the fitted lattice's nodes as cyan circles. "
                      f"The yellow box is the full-resolution crop on the right, around lenslet (row {row}, col "
                      f"{col}): detected centre ({c[0]:.3f}, {c[1]:.3f}) px, lattice node ({nodes[k][0]:.3f}, "
                      f"{nodes[k][1]:.3f}) px, residual ({r[0]:+.4f}, {r[1]:+.4f}) px.",
                 "collimated image with lenslet centres", fmt="png")


def _lenslet_quiver(lat) -> dict:
    """Residual arrows (detected minus fitted), magnified, with a key."""
    res = np.asarray(lat.residuals, np.float64).reshape(-1, 2)
    longest = float(np.max(np.linalg.norm(res, axis=1))) if len(res) else 0.0
    mag = figures.nice_floor(0.8 * lat.pitch_px / longest) if longest > 0 else 1.0
    key = figures.nice_floor(longest) if longest > 0 else 1.0
    fig = figures.quiver(lat.centres, res, lat.image_shape, magnification=mag, key=key,
                         title=f"lattice fit residuals x{mag:g}")
    return embed(fig, f"Lattice fit residuals (detected minus fitted centre) as arrows magnified x{mag:g}; RMS "
                      f"{lat.rms_px:.4f} px, max {longest:.4f} px. A systematic pattern would mean the model does "
                      f"not describe the lattice (e.g. lens distortion of the LF camera); noise-like arrows are the "
                      f"detector's own error.", "lattice fit residuals")


def _distortion_map(cal, k1: np.ndarray, used: np.ndarray) -> dict:
    """The lenslet cells where the LF camera sees them, coloured by k1."""
    array, dev = cal.model.array, cal.model.camera.device
    cells = (array.centres[:, None, :] + array.cell_vertices()[None]).reshape(-1, 2)      # (K * V, 2) metres
    cells_px = apply_homography(dev.homography, cells).reshape(len(array.centres), -1, 2)
    fig = figures.cell_map(cells_px, k1, used, (dev.height, dev.width), label="k1", title="k1 per lenslet")
    return embed(fig, "Lenslet cells where the LF camera sees them, coloured by k1 (grey: too few spots to fit). "
                      "A smooth trend across the array would point at a tilt of the collimator or the array rather "
                      "than at the lenses.", "map of k1 over the lenslets")


def _response_plot(rad, rd: dict, device: str) -> dict:
    """The camera's or projector's response: measured samples (from ``rd``) and the fitted power laws."""
    xlabel, ylabel, note = _RESPONSES[device]
    camera = device == "camera"
    samples = rd.get(f"{device}_response_samples")
    dots = [np.asarray(pts, np.float64).reshape(-1, 2) for pts in (samples or [])[:3]]
    x = np.linspace(0.0, max([1.0, *(float(d[:, 0].max()) for d in dots if len(d) and camera)]), 200)
    fig = figures.line_plot(
        [(x, x ** (1.0 / g if camera else g), CHANNEL_COLOURS[c], f"{_CHANNELS[c]}: gamma {g:.4f}")
         for c, g in enumerate(rad.camera_gamma if camera else rad.projector_gamma)],
        [(d[:, 0], d[:, 1], CHANNEL_COLOURS[c]) for c, d in enumerate(dots)], dot_size=2.5 if camera else 5.0,
        xlabel=xlabel, ylabel=ylabel, title=f"{device} response", xlim=None if camera else (0.0, 1.0), ylim=(0.0, 1.0))
    rms = None if camera else rd.get("projector_fit_rms")
    note = (note if samples else "measured samples not available") + \
        ("" if rms is None else f"; fit RMS {_vec(rms, '.2g')}")
    return embed(fig, f"{device.capitalize()} response per channel ({note}).", f"{device} response")


def _vignetting_figure(rad, rd: dict) -> dict:
    """False-colour vignetting map with a colour bar."""
    vmap = np.asarray(rad.vignetting, np.float32)
    lo, hi = float(vmap.min()), float(vmap.max())
    fig, _ = figures.image_panels(vmap, cmap="viridis", lo=lo, hi=hi, label="relative sensitivity", width=5.6,
                                  titles=("camera vignetting",))
    fit = rd.get("vignetting_fit") if isinstance(rd.get("vignetting_fit"), dict) else {}
    extra = f"; fit RMS {fit['fit_rms']:.4f} over {fit.get('pixels', '?')} pixels" if "fit_rms" in fit else ""
    return embed(fig, f"Camera vignetting: relative sensitivity, 1 at its maximum, range {lo:.3f} .. {hi:.3f} "
                      f"(degree-{rad.vignetting_poly.degree} polynomial{extra}).", "vignetting map", fmt="png")


def _flood_figure(flood) -> dict:
    """The view camera's photograph of the flood-lit board (sRGB, 99.5th percentile at 0.9)."""
    img = np.clip(np.nan_to_num(np.asarray(flood, np.float64)), 0.0, None)
    level = float(np.percentile(img, 99.5))
    fig, _ = figures.image_panels(to_display(img, 0.9 / level if level > 0 else 1.0), width=5.0,
                                  titles=("flood-lit board",))
    return embed(fig, "View camera photograph of the flood-lit board with the printed chessboard (its plane in the "
                      "world comes from it).", "flood-lit board", fmt="png")


def _pose_corners_figure(pose, pd: dict) -> dict:
    """Fringe phase image (false colour) with a sample of the decoded points and the pose's reprojections, whole
    and zoomed onto the points."""
    norm = np.asarray(pd["normalised"], np.float32)
    found = np.asarray(pd["found"] if pd.get("found") is not None else [], bool)
    if found.shape == norm.shape:
        norm = np.where(found, norm, np.nan)                             # unlit: grey
    corners = np.asarray(pose.corners_px, np.float64).reshape(-1, 2)
    reproj = np.asarray(pose.reprojected, np.float64).reshape(-1, 2)
    both, boxes, zoom = np.concatenate([corners, reproj]), [None], ""
    if len(both):                                  # a second panel zoomed onto the points, with a margin
        margin = 4 + 0.04 * max(norm.shape)
        (x0, y0), (x1, y1) = np.floor(both.min(axis=0) - margin), np.ceil(both.max(axis=0) + margin) + 1
        x0, y0, x1, y1 = max(0, int(x0)), max(0, int(y0)), min(norm.shape[1], int(x1)), min(norm.shape[0], int(y1))
        if x1 - x0 >= 2 and y1 - y0 >= 2:
            boxes.append((x0, y0, x1, y1))
            zoom = f" The right panel zooms onto the points (pixels x {x0}..{x1 - 1}, y {y0}..{y1 - 1})."
    fig, axes = figures.image_panels(norm, boxes, cmap="RdBu_r", lo=-1.0, hi=1.0, label="cos(phase)", width=9.6,
                                     titles=("fringe phase", "decoded points")[:len(boxes)])
    for ax, size in zip(axes, (5.0, 10.0)):
        ax.plot(reproj[:, 0], reproj[:, 1], "o", ms=size, mfc="none", mec="#d62728", mew=1.0)
        ax.plot(corners[:, 0], corners[:, 1], "+", ms=size, color="#1a9641", mew=1.2)
    count = f"{int(found.sum())} pixels decoded; " if found.size else ""
    return embed(fig, f"Phase of the fringes along the board's first axis as the view camera decodes it (cos of the "
                      f"phase; grey where unlit): an even sample of the decoded points as green crosses, the fitted "
                      f"pose's reprojections as red circles ({count}reprojection RMS over all points "
                      f"{_num(pose.rms_px, '.3f')} px: mostly the per-pixel noise of the phase, which the fit "
                      f"averages).{zoom}", "fringe phase with decoded points", fmt="png")


def _tone_map_codes(raw, levels: int, gamma: float = 0.5) -> np.ndarray:
    """(H, W, 3) or (H, W) raw camera codes (full scale ``levels``) of bright spots on a dark background -> (H, W)
    grey in [0, 1]: channels averaged, black point just above the background (its median plus 4 noise sigmas), the
    99.9th percentile white, display exponent ``gamma`` (0.5 lifts the spots' faint skirts)."""
    x = np.asarray(raw, np.float32) / np.float32(max(levels, 1))
    grey = x.mean(axis=2) if x.ndim == 3 else x
    if grey.ndim != 2:
        raise ValueError(f"not an image: shape {x.shape}")
    sample = grey[::max(1, grey.shape[0] // 256), ::max(1, grey.shape[1] // 256)]
    med = float(np.median(sample))
    black = med + 4 * 1.4826 * float(np.median(np.abs(sample - med)))
    peak = float(np.percentile(sample, 99.9))
    return np.clip((grey - black) / max(peak - black, 1e-6), 0.0, 1.0) ** gamma


# ---- helpers ----------------------------------------------------------------------------------------------------
def _attempt(build, *args, what: str | None = None) -> dict:
    """``build(*args)``, or where a malformed calibration or diagnostic keeps it from being made, ``{"error"}``
    (a section's values) or, given ``what``, ``{"note"}`` (a figure)."""
    try:
        return build(*args)
    except _SKIPPED as exc:
        why = f"{type(exc).__name__}: {exc}"
        return {"note": f"{what}: left out ({why})."} if what else {"error": why}

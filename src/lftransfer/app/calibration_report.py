"""An HTML report of a rig calibration, with pictures (for the people who check a calibration by eye).

:func:`write_calibration_report` writes one self-contained file, ``calibration_report.html``: raster pictures
are PNG (OpenCV) embedded as ``data:`` URIs, plots are inline SVG written here as text; nothing is fetched when
the file is opened. Its sections follow the calibration's steps (:mod:`lftransfer.calibration.rig`):

1. summary: the calibration file's key numbers (the measured point light among them: its position, how far it
   moved from the scene file's, the fit's residual) and, if given, the errors against a simulated rig's hidden
   truth (:func:`lftransfer.sim.verify.calibration_errors`) with the project's targets, each marked pass or fail;
2. lenslet centres: the collimated image with the detected centres and the fitted lattice, a full-resolution
   crop, and the lattice fit's residuals as arrows;
3. lenslet distortion: histograms of the per-lenslet k1 and k2 and a map of k1 over the lenslets;
4. projector mapping: the camera-to-projector homography;
5. radiometry: the camera and projector responses, cross-talk, black level, vignetting, brightness;
6. global pose: the view camera's photographs of the board, the decoded fringe points and their reprojections.

A calibration read from a file (:func:`lftransfer.calibration.rig.load_calibration`) has no lattice fit, no
distortion fit, no projector fit and no diagnostics: those parts say so, and whatever its model still holds
(per-lenslet distortion, the devices' homographies, the radiometric measurements) is shown. A missing or
malformed diagnostic leaves its picture out; it never stops the report.
"""

from __future__ import annotations

import base64
import html
import itertools
import math
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from lftransfer.calibration.targets import TARGETS as CALIBRATION_TARGETS
from lftransfer.imageio_utils import to_display, write_text

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
}

_CHANNELS = ("R", "G", "B")
_CHANNEL_COLOURS = ("#d62728", "#2ca02c", "#1f77b4")
_MAX_WIDTH = 1000             # raster pictures are downscaled to this width at most
_MIN_WIDTH = 640              # ... and small ones enlarged (integer factor, nearest neighbour) to about this
_GREEN, _RED, _CYAN, _ORANGE = (40, 230, 40), (240, 40, 40), (40, 220, 255), (255, 150, 30)

_CSS = """
body{font-family:system-ui,-apple-system,"Segoe UI",Helvetica,Arial,sans-serif;max-width:1120px;margin:1.5em auto;
padding:0 1em;color:#222;line-height:1.45}
h1{margin-bottom:.2em}h2{border-bottom:1px solid #ccc;padding-bottom:.2em;margin-top:2em}
nav a{margin-right:1em}
table{border-collapse:collapse;margin:.6em 0}
td,th{border:1px solid #ccc;padding:.25em .6em;text-align:left;vertical-align:top}
th{background:#f3f3f3}
td.num{font-family:ui-monospace,Menlo,Consolas,monospace;text-align:right;white-space:nowrap}
td.pass{background:#d8f3d8;color:#145214;font-weight:600}td.fail{background:#f8d4d4;color:#7a1010;font-weight:600}
td.heat{text-align:center;font-family:ui-monospace,Menlo,Consolas,monospace;min-width:5em}
.figs{display:flex;flex-wrap:wrap;gap:1.2em;align-items:flex-start}
figure .figs{gap:.5em}
figure{margin:.5em 0}figcaption{font-size:.88em;color:#555;max-width:560px}
img{max-width:100%;height:auto;image-rendering:pixelated;border:1px solid #ddd}
.note{color:#8a5a00;font-style:italic}
.explain{max-width:60em}
"""


# ---- public API -------------------------------------------------------------------------------------------------
def write_calibration_report(path, calibration, errors: dict | None = None) -> Path:
    """Write the calibration report as one self-contained HTML file, atomically.

    Args:
        path: a folder (the file is ``calibration_report.html`` in it) or a file name ending in ``.html``;
            missing folders are created.
        calibration: :class:`lftransfer.calibration.rig.Calibration`.
        errors: errors against a simulated rig's hidden truth (:func:`lftransfer.sim.verify.calibration_errors`),
            shown with the project's targets; None to leave that table out.

    Returns:
        Path of the written file.
    """
    path = Path(path)
    if path.suffix.lower() not in (".html", ".htm"):
        path = path / REPORT_NAME
    text = render_calibration_report(calibration, errors)
    return write_text(path, text)


def render_calibration_report(calibration, errors: dict | None = None) -> str:
    """The calibration report as an HTML document (see :func:`write_calibration_report`).

    Returns:
        the document's text.
    """
    diag = calibration.diagnostics if isinstance(calibration.diagnostics, dict) else {}
    builders = (lambda: _summary_section(calibration, errors), lambda: _lenslet_section(calibration, diag),
                lambda: _distortion_section(calibration), lambda: _projector_section(calibration),
                lambda: _radiometry_section(calibration, diag), lambda: _pose_section(calibration, diag))
    sections = []
    for i, (name, build) in enumerate(zip(SECTIONS, builders), 1):
        body = _guarded(build, f"section {name!r}")
        sections.append(f'<section id="s{i}">\n<h2>{i}. {_esc(name)}</h2>\n{body}\n</section>')
    nav = " ".join(f'<a href="#s{i}">{i}. {_esc(n)}</a>' for i, n in enumerate(SECTIONS, 1))
    a = calibration.model.array
    subtitle = (f"{a.rows} x {a.cols} {a.lattice} lens array; LF camera {calibration.model.camera.device.width} x "
                f"{calibration.model.camera.device.height} px, projector {calibration.model.projector.device.width}"
                f" x {calibration.model.projector.device.height} px")
    return "\n".join([
        "<!DOCTYPE html>", '<html lang="en">', "<head>", '<meta charset="utf-8">',
        '<meta name="viewport" content="width=device-width, initial-scale=1">',
        "<title>Light field transfer rig: calibration report</title>", f"<style>{_CSS}</style>", "</head>", "<body>",
        "<h1>Light field transfer rig: calibration report</h1>", f"<p>{_esc(subtitle)}</p>", f"<nav>{nav}</nav>",
        *sections, "</body>", "</html>", ""])


# ---- sections ---------------------------------------------------------------------------------------------------
def _summary_section(cal, errors: dict | None) -> str:
    """Key numbers of the calibration file and, if given, the errors against the hidden truth."""
    data = cal.to_json()
    la, pose, rad = data["lens_array"], data["pose"], data["radiometry"]
    rows = [
        ("lens array", "lattice", f"{la['lattice']}, {la['rows']} x {la['cols']} lenslets", ""),
        ("lens array", "pitch", f"{la['pitch_m'] * 1e3:.4f}", "mm"),
        ("lens array", "focal length", f"{la['focal_length_m'] * 1e3:.4f}", "mm"),
        ("lens array", "in-plane rotation", f"{la['rotation_deg']:.4f}", "deg"),
        ("lens array", "offset (x, y)", _vec(np.asarray(la["offset_m"]) * 1e3, ".3f"), "mm"),
        ("lens array", "tilt (about x, about y)", _vec(la["tilt_deg"], ".4f"), "deg"),
        ("lens array", "scale (true / nominal pitch)", f"{pose['scale']:.6f}", ""),
    ]
    if "lenslet_centres" in data:
        lc, lat = data["lenslet_centres"], cal.lattice
        rows += [("lenslet centres", "lenslets found", f"{len(lc['centres_px'])} ({lat.rejected} dropped)", ""),
                 ("lenslet centres", "pitch in the LF camera", f"{lc['pitch_px']:.3f}", "px"),
                 ("lenslet centres", "rotation in the LF camera", f"{lc['rotation_deg']:.3f}", "deg"),
                 ("lenslet centres", "lattice fit residual, RMS", f"{lc['rms_px']:.4f}", "px"),
                 ("lenslet centres", "lattice fit residual, max", f"{lat.max_residual_px:.4f}", "px"),
                 ("lenslet centres", "spot blur sigma", f"{lat.spot_sigma_px:.2f}", "px")]
    else:
        rows.append(("lenslet centres", "lattice fit", NOT_AVAILABLE, ""))
    if "distortion" in data:
        rows += [("lenslet distortion", "collimator mount angle", f"{data['distortion']['mount_angle_deg']:.4f}",
                  "deg"),
                 ("lenslet distortion", "fit residual, RMS", f"{data['distortion']['rms']:.3g}", "focal lengths")]
    else:
        rows.append(("lenslet distortion", "fit", NOT_AVAILABLE, ""))
    k1 = np.asarray(cal.model.camera.device.distortion)[:, 0]
    rows.append(("lenslet distortion", "k1, median (min .. max)",
                 f"{np.median(k1):.4f} ({k1.min():.4f} .. {k1.max():.4f})", ""))
    if "projector_mapping" in data:
        pm = data["projector_mapping"]
        rows += [("projector mapping", "residual, RMS", f"{pm['rms_px']:.3f}", "projector px"),
                 ("projector mapping", "camera pixels used", f"{pm['pixels']}", "")]
    else:
        rows.append(("projector mapping", "Gray-code fit", NOT_AVAILABLE, ""))
    rows += [
        ("global pose", "projected fringe points, reprojection RMS", _num(pose["rms_px"], ".3f"), "view px"),
        ("global pose", "printed chessboard (solvePnP), RMS", _num(pose["pnp_rms_px"], ".3f"), "view px"),
        ("global pose", "3-D residual of the pose fit, RMS", _num(pose["residual_mm"], ".3f"), "mm"),
        ("radiometry", "camera gamma (R, G, B)", _vec(rad["camera_gamma"], ".4f"), ""),
        ("radiometry", "projector gamma (R, G, B)", _vec(rad["projector_gamma"], ".4f"), ""),
        ("radiometry", "camera exposure", f"{rad['camera_exposure']:.5g}", "sr m^2 / W"),
        ("radiometry", "projector max_radiance", f"{rad['max_radiance']:.5g}", "W / (m^2 sr)"),
        ("radiometry", "black level (R, G, B)", _vec(rad["black_level"], ".5f"), "of max_radiance"),
        *_light_rows(cal.light),
        ("devices", "LF camera", f"{data['lf_camera']['width']} x {data['lf_camera']['height']}, "
                                  f"{data['lf_camera']['bits']} bit", "px"),
        ("devices", "projector", f"{data['projector']['width']} x {data['projector']['height']}, "
                                 f"{data['projector']['bits']} bit", "px"),
    ]
    out = ['<p class="explain">The numbers the calibration file holds, step by step. The lens array\'s pose is in '
           "the view camera's world; the pixel numbers are measured in the LF camera (lenslet centres), in the "
           "projector (mapping) and in the view camera (pose).</p>",
           _table(("step", "quantity", "value", "unit"), rows, numeric=(2,))]
    if errors:
        out += ["<h3>Against the simulator's hidden truth</h3>",
                '<p class="explain">The simulated rig knows the truth it was built with; these errors compare the '
                "calibration with it (verification only: the calibration never sees it). A target is the "
                "project's requirement; rows without one are for information.</p>",
                _errors_table(errors)]
    return "\n".join(out)


def _light_rows(light) -> list[tuple[str, str, str, str]]:
    """The summary's rows of the point light step (:class:`lftransfer.calibration.light.LightFit`, or None)."""
    if light is None:
        return [("point light", "position", "not measured: the scene file's position stands", "")]
    return [("point light", "position (x, y, z)", _vec(light.position * 1e3, ".2f"), "mm"),
            ("point light", "moved from the scene file's position", _num(light.shift_mm, ".2f"), "mm"),
            ("point light", "fit residual, RMS (relative)", _num(100 * light.residual_rms, ".3f"), "%"),
            ("point light", "standard error from the residuals (x, y, z)", _vec(light.std_mm, ".3f"), "mm"),
            ("point light", "boards, view pixels", f"{light.boards}, {light.pixels}", "")]


def _lenslet_section(cal, diag: dict) -> str:
    """Collimated image with the centres and lattice, a full-resolution crop, the residual quiver plot."""
    lat = cal.lattice
    if lat is None:
        return _explain("An on-axis collimated source focuses behind every lenslet into one small spot; the spots' "
                        "sub-pixel centres and the lattice fitted through them fix the LF camera's homography.") + \
            f'<p class="note">Lattice fit {NOT_AVAILABLE}.</p>'
    text = (f"A collimated source on the array's axis focuses behind every lenslet into one small spot, photographed "
            f"by the LF camera. The spots' centres are found to a fraction of a pixel (Gaussian-windowed centroids "
            f"on the background-subtracted image; spot sigma {lat.spot_sigma_px:.2f} px), and a {lat.lattice} lattice "
            f"is fitted through them (a homography"
            f"{'' if not np.any(lat.distortion) else ', then the main lens' + chr(39) + 's radial distortion'}): "
            f"{len(lat.centres)} lenslets, pitch {lat.pitch_px:.3f} px, "
            f"rotation {lat.rotation_deg:.3f} deg, residual RMS {lat.rms_px:.4f} px (max "
            f"{lat.max_residual_px:.4f} px). The homography from the rig file's nominal lattice to these centres "
            f"is the LF camera's model.")
    figs = []
    raw = diag.get("collimated")
    if raw is not None:
        levels = cal.model.camera.levels
        figs.append(_guarded(lambda: _lenslet_overview(raw, lat, levels), "collimated image"))
        figs.append(_guarded(lambda: _lenslet_inset(raw, lat, levels), "full-resolution crop"))
    else:
        figs.append(f'<p class="note">Collimated image {NOT_AVAILABLE}.</p>')
    figs.append(_guarded(lambda: _lenslet_quiver(lat), "residual plot"))
    return _explain(text) + _figs(figs)


def _distortion_section(cal) -> str:
    """Histograms of k1 and k2 and the k1 map over the lenslets."""
    fit = cal.distortion
    model = cal.model
    coeffs = np.asarray(model.camera.device.distortion, np.float64)
    if fit is not None:
        coeffs = np.asarray(fit.coefficients, np.float64)
        used = np.asarray(fit.spots) >= 4
        text = (f"A collimated beam tilted to a 5 x 5 grid of known directions focuses behind each lenslet at an "
                f"offset from its centre; against the ideal offsets this gives each lenslet OpenCV's radial "
                f"distortion, x_d = x_n (1 + k1 r^2 + k2 r^4), by linear least squares, with one global angle for "
                f"the collimator mount's turn about the array's axis ({np.degrees(fit.mount_angle):.4f} deg). "
                f"{int(used.sum())} of {len(used)} lenslets had enough spots; residual RMS {fit.rms:.3g} focal "
                f"lengths. The camera and the projector look through the same lenslets, so both use these.")
    else:
        used = np.ones(len(coeffs), bool)
        text = (f"Per-lenslet radial distortion (k1, k2) from the tilted-collimator sweep. The fit's statistics are "
                f"{NOT_AVAILABLE}; the coefficients below are the model's.")
    figs = [
        _guarded(lambda: _figure(_svg_histogram(coeffs[used, 0], xlabel="k1", title="k1 per lenslet",
                                                colour="#4c72b0"), "Histogram of k1 over the lenslets."), "k1"),
        _guarded(lambda: _figure(_svg_histogram(coeffs[used, 1], xlabel="k2", title="k2 per lenslet",
                                                colour="#dd8452"), "Histogram of k2 over the lenslets."), "k2"),
        _guarded(lambda: _distortion_map(cal, coeffs[:, 0], used), "k1 map"),
    ]
    return _explain(text) + _figs(figs)


def _projector_section(cal) -> str:
    """The camera-to-projector homography and its residual."""
    fit = cal.projector_fit
    if fit is not None:
        H = np.asarray(fit.homography, np.float64)
        text = (f"With a diffuser at the lenslets' focal plane the LF camera sees the projector's pixels directly. "
                f"Binary Gray-code patterns, each with its inverse, give every camera pixel the projector column "
                f"and row it sees; a homography fitted by least squares to {fit.pixels} camera pixels (after RANSAC "
                f"against stray codes) maps camera pixels to projector pixels. Residual RMS {fit.rms_px:.3f} "
                f"projector px: it includes the codes' own one-pixel quantisation (about 0.41 px), which the fit "
                f"averages away.")
    else:
        cam, prj = cal.model.camera.device.homography, cal.model.projector.device.homography
        H = prj @ np.linalg.inv(cam)
        H = H / H[2, 2]
        text = (f"Camera pixel to projector pixel homography (Gray codes on a focal-plane diffuser). The Gray-code "
                f"fit is {NOT_AVAILABLE}; the matrix below is the model's (projector homography times the inverse "
                f"of the camera's).")
    jac = _homography_jacobian(H, np.array([cal.model.camera.device.width, cal.model.camera.device.height]) / 2 - 0.5)
    rows = [[f"{v:.6g}" for v in row] for row in H]
    matrix = _table(("", "", ""), rows, numeric=(0, 1, 2), header=False)
    scale = math.sqrt(abs(np.linalg.det(jac)))
    return (_explain(text) + "<p>Camera pixel (x, y, 1) &rarr; projector pixel:</p>" + matrix +
            f"<p>At the camera image's centre one camera pixel covers about {scale:.4f} projector pixels.</p>")


def _radiometry_section(cal, diag: dict) -> str:
    """Response curves, cross-talk heat map, black level, vignetting map, brightness numbers."""
    rad = cal.radiometry
    rd = rad.diagnostics if isinstance(rad.diagnostics, dict) else {}
    text = ("The camera's response comes from an exposure bracket of a projector ramp seen on the focal-plane "
            "diffuser: log code against log exposure has slope 1/gamma. A flat field, linearised, gives the "
            "vignetting (a degree-4 polynomial). Uniform projector images per channel, linearised and "
            "flat-fielded, give the projector's response (code^gamma), its colour cross-talk and black level. "
            "Finally a grey board of known albedo in front of the array, measured by the view camera and rendered "
            "with the calibrated model, fixes the projector's absolute brightness (max_radiance), and the same "
            "board seen by both cameras fixes the LF camera's exposure. "
            f"Camera gamma {_vec(rad.camera_gamma, '.4f')}, projector gamma {_vec(rad.projector_gamma, '.4f')}, "
            f"max_radiance {rad.max_radiance:.5g} W m^-2 sr^-1, camera exposure {rad.camera_exposure:.5g}.")
    figs = [_guarded(lambda: _camera_response_plot(rad, rd), "camera response"),
            _guarded(lambda: _projector_response_plot(rad, rd), "projector response")]
    tables = [
        _figure(_heatmap_table(rad.cross_talk, [f"light {c}" for c in _CHANNELS],
                               [f"code {c}" for c in _CHANNELS]),
                "Projector cross-talk C (column j: the light of projector channel j; mean of the diagonal 1)."),
        _figure(_table(("", *_CHANNELS), [("black level", *[f"{v:.5f}" for v in rad.black_level])],
                       numeric=(1, 2, 3)), "Black level: light at code 0, fraction of max_radiance."),
    ]
    brightness = _brightness_rows(rad, rd, diag.get("exposure"))
    tables.append(_figure(_table(("measurement", "value", "unit"), brightness, numeric=(1,)),
                          "Brightness and exposure measurements."))
    vig = _guarded(lambda: _vignetting_figure(rad, rd), "vignetting map")
    return _explain(text) + _figs(figs) + _figs(tables) + _figs([vig])


def _pose_section(cal, diag: dict) -> str:
    """Board photographs with the decoded fringe points and the pose's reprojections, and the residual table."""
    pose = cal.pose
    text = ("A diffuse board with a chessboard printed on it is held in front of the array; the view camera "
            "photographs it flood-lit, and the printed chessboard gives the board's plane in the world "
            "(solvePnP). The rig then projects light fields that draw phase-shifted sinusoidal fringes along the "
            "board's two axes; their phase at each view camera pixel is the model-frame point drawn there, "
            "whatever the lenslets' blur. Back-projected onto the board's plane, these points give the array's "
            "tilt, rotation, offset and scale by least squares, over boards at two depths, in two rounds (the "
            "second draws the fringes on each board where the first round says it stands). "
            f"Rotation {np.degrees(pose.rotation):.4f} deg, tilt {_vec(np.degrees(pose.tilt), '.4f')} deg, offset "
            f"{_vec(np.asarray(pose.offset) * 1e3, '.3f')} mm, scale {pose.scale:.6f}; reprojection RMS "
            f"{_num(pose.rms_px, '.3f')} px, 3-D residual {_num(pose.residual_mm, '.3f')} mm.")
    pd = diag.get("pose") if isinstance(diag.get("pose"), dict) else None
    figs = []
    if pd is None:
        figs.append(f'<p class="note">Board photographs {NOT_AVAILABLE}.</p>')
    else:
        images = pd.get("images") if isinstance(pd.get("images"), dict) else {}
        if images.get("flood") is not None:
            figs.append(_guarded(lambda: _figure(_png_img(_linear_display(images["flood"]), "flood-lit board"),
                                                 "View camera photograph of the flood-lit board with the printed "
                                                 "chessboard (its plane in the world comes from it)."), "flood"))
        if pd.get("normalised") is not None:
            figs.append(_guarded(lambda: _pose_corners_figure(pose, pd), "corners"))
    corners = np.asarray(pose.corners_px, np.float64).reshape(-1, 2)
    reproj = np.asarray(pose.reprojected, np.float64).reshape(-1, 2)
    if len(corners) and len(corners) == len(reproj):
        r = reproj - corners
        rows = [(str(i), f"{c[0]:.3f}", f"{c[1]:.3f}", f"{p[0]:.3f}", f"{p[1]:.3f}", f"{d[0]:+.3f}", f"{d[1]:+.3f}",
                 f"{np.hypot(*d):.3f}") for i, (c, p, d) in enumerate(zip(corners, reproj, r))]
        table = _table(("point", "detected x", "detected y", "reprojected x", "reprojected y", "dx", "dy", "|r|"),
                       rows, numeric=tuple(range(8)))
        figs.append(_figure(table, f"An even sample of the decoded points (view camera pixels): reprojection RMS over all "
                                   f"{_num(pose.rms_px, '.3f')} px."))
    else:
        figs.append(f'<p class="note">Per-point residuals {NOT_AVAILABLE}.</p>')
    return _explain(text) + _figs(figs)


# ---- section pictures ---------------------------------------------------------------------------------------------
def _inset_box(lat) -> tuple[int, int, int, int, int]:
    """The full-resolution crop: around the lenslet nearest the image's top-left corner, a few spot sigmas wide.

    Returns:
        (index into ``lat.centres``, x0, y0, x1, y1) with the crop ``[y0:y1, x0:x1]``.
    """
    h, w = lat.image_shape
    k = int(np.argmin(lat.centres.sum(axis=1)))
    c = lat.centres[k]
    half = int(np.clip(math.ceil(5 * lat.spot_sigma_px), 6, max(6, 0.45 * lat.pitch_px)))
    x0, y0 = max(0, int(round(c[0])) - half), max(0, int(round(c[1])) - half)
    return k, x0, y0, min(w, x0 + 2 * half + 1), min(h, y0 + 2 * half + 1)


def _lenslet_overview(raw: np.ndarray, lat, levels: int) -> str:
    """The whole collimated image, detected centres (crosses) and fitted lattice nodes (circles)."""
    img = _tone_map_codes(raw, levels)
    h, w = img.shape[:2]
    f = _display_factor(w)
    disp = _resize(img, f)
    size = max(4.0, 0.2 * lat.pitch_px * f)
    for p in lat.predicted(lat.indices):
        _circle(disp, _to_display(p, f), size, _CYAN)
    for p in lat.centres:
        _cross(disp, _to_display(p, f), size, _ORANGE, gap=0.45 * size)
    _, x0, y0, x1, y1 = _inset_box(lat)
    cv2.rectangle(disp, _fixed(_to_display((x0 - 0.5, y0 - 0.5), f) + 0.5),
                  _fixed(_to_display((x1 - 0.5, y1 - 0.5), f) - 0.5), (255, 255, 0), 1, cv2.LINE_AA, _SHIFT)
    caption = (f"Collimated image ({w} x {h} px, grey, black point above the background noise, gamma 0.5, shown "
               f"at x{f:.3g}): detected spot centres as orange crosses, the fitted lattice's nodes as cyan circles; "
               f"the yellow box is the full-resolution crop.")
    return _figure(_png_img(disp, "collimated image with lenslet centres"), caption)


def _lenslet_inset(raw: np.ndarray, lat, levels: int) -> str:
    """A full-resolution crop around the lenslet nearest the image's top-left corner, pixels enlarged."""
    img = _tone_map_codes(raw, levels)
    k, x0, y0, x1, y1 = _inset_box(lat)
    crop = img[y0:y1, x0:x1]
    f = max(1, int(round(400 / max(crop.shape[1], 1))))
    disp = cv2.resize(crop, (crop.shape[1] * f, crop.shape[0] * f), interpolation=cv2.INTER_NEAREST)
    if f >= 6:                                                       # faint pixel grid
        disp[::f, :] = np.maximum(disp[::f, :], 45)
        disp[:, ::f] = np.maximum(disp[:, ::f], 45)
    c = lat.centres[k]
    node = lat.predicted(lat.indices[k:k + 1])[0]
    _circle(disp, _to_display(node - (x0, y0), f), 0.5 * f, _CYAN)
    _cross(disp, _to_display(c - (x0, y0), f), 2.0 * f, _ORANGE, gap=0.25 * f)
    r = c - node
    caption = (f"Full-resolution crop (pixels x {x0}..{x1 - 1}, y {y0}..{y1 - 1}, each shown as {f} x {f}) around "
               f"lenslet (row {lat.indices[k][0]}, col {lat.indices[k][1]}): detected centre ({c[0]:.3f}, "
               f"{c[1]:.3f}) px (orange cross), lattice node ({node[0]:.3f}, {node[1]:.3f}) px (cyan circle), "
               f"residual ({r[0]:+.4f}, {r[1]:+.4f}) px.")
    return _figure(_png_img(disp, "full-resolution crop of a lenslet spot"), caption)


def _lenslet_quiver(lat) -> str:
    """Residual arrows (detected minus fitted), magnified, with a scale bar."""
    res = np.asarray(lat.residuals, np.float64)
    longest = float(np.max(np.linalg.norm(res, axis=1))) if len(res) else 0.0
    mag = _nice_floor(0.8 * lat.pitch_px / longest) if longest > 0 else 1.0
    bar = _nice_floor(longest) if longest > 0 else 1.0
    svg = _svg_quiver(lat.centres, res, mag, lat.image_shape, bar, "px",
                      title=f"lattice fit residuals x{_fmt_plain(mag)}")
    caption = (f"Lattice fit residuals (detected minus fitted centre) as arrows magnified x{_fmt_plain(mag)}; "
               f"RMS {lat.rms_px:.4f} px, max {longest:.4f} px. A systematic pattern would mean the homography "
               f"does not describe the lattice (e.g. lens distortion of the LF camera); noise-like arrows are the "
               f"detector's own error.")
    return _figure(svg, caption)


def _distortion_map(cal, k1: np.ndarray, used: np.ndarray) -> str:
    """SVG of the lenslet cells in the LF camera image, coloured by k1."""
    model = cal.model
    array, dev = model.array, model.camera.device
    cells = array.centres[:, None, :] + array.cell_vertices()[None]            # (K, V, 2) metres
    cells_px = _apply_homography(dev.homography, cells.reshape(-1, 2)).reshape(cells.shape)
    svg = _svg_cell_map(cells_px, k1, used, (dev.height, dev.width), label="k1", title="k1 per lenslet")
    caption = ("Lenslet cells where the LF camera sees them, coloured by k1 (grey: too few spots to fit). A "
               "smooth trend across the array would point at a tilt of the collimator or the array rather than at "
               "the lenses.")
    return _figure(svg, caption)


def _camera_response_plot(rad, rd: dict) -> str:
    """Camera response: measured (exposure x signal, code) samples and the fitted power laws."""
    samples = rd.get("camera_response_samples")
    series, top = [], 1.0
    if samples:
        for c, pts in enumerate(samples[:3]):
            pts = np.asarray(pts, np.float64).reshape(-1, 2)
            if len(pts):
                top = max(top, float(pts[:, 0].max()))
                series.append(_Series(pts[:, 0], pts[:, 1], _CHANNEL_COLOURS[c], None, "dots"))
    x = np.linspace(0.0, top, 200)
    for c in range(3):
        series.append(_Series(x, np.clip(x, 0, None) ** (1.0 / rad.camera_gamma[c]), _CHANNEL_COLOURS[c],
                              f"{_CHANNELS[c]}: gamma {rad.camera_gamma[c]:.4f}", "line"))
    svg = _svg_line_plot(series, xlabel="relative exposure x linear signal", ylabel="normalised camera code",
                         title="camera response", ylim=(0.0, 1.0))
    note = "dots: pixels of the exposure bracket; lines: code = signal^(1/gamma)" if samples else \
        "measured samples not available"
    return _figure(svg, f"Camera response per channel ({note}).")


def _projector_response_plot(rad, rd: dict) -> str:
    """Projector response: measured (code, drive) samples and the fitted power laws."""
    samples = rd.get("projector_response_samples")
    series = []
    if samples:
        for c, pts in enumerate(samples[:3]):
            pts = np.asarray(pts, np.float64).reshape(-1, 2)
            series.append(_Series(pts[:, 0], pts[:, 1], _CHANNEL_COLOURS[c], None, "dots", radius=3.5))
    x = np.linspace(0.0, 1.0, 200)
    for c in range(3):
        series.append(_Series(x, x ** rad.projector_gamma[c], _CHANNEL_COLOURS[c],
                              f"{_CHANNELS[c]}: gamma {rad.projector_gamma[c]:.4f}", "line"))
    svg = _svg_line_plot(series, xlabel="normalised projector code", ylabel="normalised drive (light)",
                         title="projector response", xlim=(0.0, 1.0), ylim=(0.0, 1.0))
    rms = rd.get("projector_fit_rms")
    extra = f"; fit RMS {_vec(rms, '.2g')}" if rms is not None else ""
    note = "dots: measured, black level subtracted; lines: drive = code^gamma" if samples else \
        "measured samples not available"
    return _figure(svg, f"Projector response per channel ({note}{extra}).")


def _vignetting_figure(rad, rd: dict) -> str:
    """False-colour vignetting map with a colour bar."""
    vmap = np.asarray(rad.vignetting, np.float32)
    lo, hi = float(vmap.min()), float(vmap.max())
    lut = _colormap_lut(cv2.COLORMAP_VIRIDIS)
    img = _false_colour(vmap, lo, hi, lut)
    img = _resize(img, _display_factor(img.shape[1]))
    fit = rd.get("vignetting_fit") if isinstance(rd.get("vignetting_fit"), dict) else {}
    extra = f"; fit RMS {fit['fit_rms']:.4f} over {fit.get('pixels', '?')} pixels" if "fit_rms" in fit else ""
    body = _png_img(img, "vignetting map") + _svg_colour_bar(lo, hi, lut, "relative sensitivity")
    return _figure(f'<div class="figs">{body}</div>',
                   f"Camera vignetting: relative sensitivity, 1 at its maximum, range {lo:.3f} .. {hi:.3f} "
                   f"(degree-{rad.vignetting_poly.degree} polynomial{extra}).")


def _pose_corners_figure(pose, pd: dict) -> str:
    """Fringe phase image (false colour) with a sample of the decoded points and the pose's reprojections, whole
    and zoomed."""
    norm = np.asarray(pd["normalised"], np.float32)
    lut = _diverging_lut()
    img = _false_colour(norm, -1.0, 1.0, lut)
    corners = np.asarray(pose.corners_px, np.float64).reshape(-1, 2)
    reproj = np.asarray(pose.reprojected, np.float64).reshape(-1, 2)
    f = _display_factor(img.shape[1])
    disp = _resize(img, f)
    _draw_corners(disp, corners, reproj, f, max(4.0, 1.2 * f))
    found = np.asarray(pd.get("found") if pd.get("found") is not None else [], bool).ravel()
    count = f"{int(found.sum())} pixels decoded; " if found.size else ""
    pictures = [_png_img(disp, "fringe phase with sample points")]
    both = np.concatenate([corners, reproj]) if len(corners) else np.zeros((0, 2))
    zoom = ""
    if len(both):
        spacing = float(np.median(np.linalg.norm(np.diff(corners, axis=0), axis=1))) if len(corners) > 1 else 10.0
        margin = max(6.0, 0.8 * spacing)
        h, w = norm.shape
        x0, y0 = (max(0, int(math.floor(v - margin))) for v in both.min(axis=0))
        x1, y1 = (int(math.ceil(v + margin)) + 1 for v in both.max(axis=0))
        x1, y1 = min(w, x1), min(h, y1)
        if x1 - x0 >= 2 and y1 - y0 >= 2:
            z = max(1, int(round(480 / (x1 - x0))))
            crop = cv2.resize(img[y0:y1, x0:x1], ((x1 - x0) * z, (y1 - y0) * z), interpolation=cv2.INTER_NEAREST)
            _draw_corners(crop, corners - (x0, y0), reproj - (x0, y0), z, max(8.0, 1.5 * z))
            pictures.append(_png_img(crop, "corners, zoomed"))
            zoom = f" The second picture zooms onto the corners (pixels x {x0}..{x1 - 1}, y {y0}..{y1 - 1}, x{z})."
    body = "".join(pictures) + _svg_colour_bar(-1.0, 1.0, lut, "cos(phase)")
    return _figure(f'<div class="figs">{body}</div>',
                   f"Phase of the fringes along the board's first axis as the view camera decodes it (cos of the "
                   f"phase, shown at x{f:.3g}; 0 where unlit): an even sample of the decoded points as green "
                   f"crosses, the fitted pose's reprojections as red circles ({count}reprojection RMS over all "
                   f"points {_num(pose.rms_px, '.3f')} px: mostly the per-pixel noise of the phase, which the fit "
                   f"averages).{zoom}")


def _draw_corners(img: np.ndarray, corners: np.ndarray, reproj: np.ndarray, factor: float, size: float) -> None:
    """Detected corners (green crosses) and reprojections (red circles) on an image scaled by ``factor``."""
    for p in reproj:
        _circle(img, _to_display(p, factor), 0.7 * size, _RED)
    for p in corners:
        _cross(img, _to_display(p, factor), size, _GREEN)


def _brightness_rows(rad, rd: dict, exposure) -> list[tuple[str, str, str]]:
    """Rows of the brightness and exposure table, from whatever measurements are present."""
    rows = [("projector max_radiance", f"{rad.max_radiance:.5g}", "W / (m^2 sr)"),
            ("camera exposure", f"{rad.camera_exposure:.5g}", "sr m^2 / W")]
    if "board_centre_m" in rd:
        rows.append(("board centre (model frame)", _vec(rd["board_centre_m"], ".3f"), "m"))
    if "board_pixels" in rd:
        rows.append(("board pixels compared", str(rd["board_pixels"]), ""))
    if "board_measured_mean" in rd:
        rows.append(("board radiance measured by the view camera (R, G, B)", _vec(rd["board_measured_mean"], ".4g"),
                     "W / (m^2 sr)"))
    if "board_ratio_per_channel" in rd:
        rows.append(("measured / rendered at max_radiance 1 (R, G, B)", _vec(rd["board_ratio_per_channel"], ".5g"),
                     ""))
    if "exposure_times_diffuser" in rd:
        rows.append(("diffuser transmission x camera exposure", f"{rd['exposure_times_diffuser']:.5g}", ""))
    if isinstance(exposure, dict):
        if "view_radiance" in exposure:
            rows.append(("exposure board: view camera radiance (R, G, B)", _vec(exposure["view_radiance"], ".4g"),
                         "W / (m^2 sr)"))
        if "lf_radiance" in exposure:
            rows.append(("exposure board: LF camera radiance before correction (R, G, B)",
                         _vec(exposure["lf_radiance"], ".4g"), "W / (m^2 sr)"))
        if "rays" in exposure:
            rows.append(("exposure board: LF camera rays used", str(exposure["rays"]), ""))
    captures = rd.get("captures")
    if isinstance(captures, dict):
        rows.append(("captures (focal plane, board)",
                     f"{captures.get('focal_plane', '?')}, {captures.get('board', '?')}", ""))
    return rows


def _errors_table(errors: dict) -> str:
    """Errors against the hidden truth, with the targets and pass/fail marks."""
    head = ("quantity", "error", "unit", "target", "")
    rows = []
    for key in [*(k for k in _ERROR_ROWS if k in errors), *(k for k in errors if k not in _ERROR_ROWS)]:
        label, unit, factor = _ERROR_ROWS.get(key, (key, "", 1.0))
        value = errors[key]
        if not isinstance(value, (int, float, np.integer, np.floating)) or isinstance(value, bool):
            continue
        shown = str(int(value)) if isinstance(value, (int, np.integer)) else f"{float(value) * factor:.5g}"
        target = TARGETS.get(key)
        if target is None:
            cells = (_esc(label), shown, _esc(unit), "", "")
            rows.append("<tr>" + "".join(f'<td class="num">{c}</td>' if i == 1 else f"<td>{c}</td>"
                                         for i, c in enumerate(cells)) + "</tr>")
            continue
        verdict = "pass" if target.met(value) else "fail"
        rows.append(f"<tr><td>{_esc(label)}</td><td class=\"num\">{shown}</td><td>{_esc(unit)}</td>"
                    f"<td class=\"num\">&le; {target.bound * factor:.4g}</td>"
                    f"<td class=\"{verdict}\">{verdict}</td></tr>")
    header = "".join(f"<th>{_esc(h)}</th>" for h in head)
    return f"<table>\n<tr>{header}</tr>\n" + "\n".join(rows) + "\n</table>"


# ---- raster helpers -----------------------------------------------------------------------------------------------
def _png_data_uri(image: np.ndarray) -> str:
    """PNG data URI of an image.

    Args:
        image: (H, W, 3) uint8 RGB or (H, W) uint8.

    Returns:
        ``data:image/png;base64,...``.
    """
    img = np.ascontiguousarray(image)
    if img.ndim == 3:
        img = cv2.cvtColor(img, cv2.COLOR_RGB2BGR)
    ok, buf = cv2.imencode(".png", img, [cv2.IMWRITE_PNG_COMPRESSION, 9])
    if not ok:
        raise ValueError("PNG encoding failed")
    return "data:image/png;base64," + base64.b64encode(buf.tobytes()).decode("ascii")


def _png_img(image: np.ndarray, alt: str) -> str:
    """``<img>`` tag of an (H, W, 3) uint8 RGB image, at its own size."""
    h, w = image.shape[:2]
    return f'<img src="{_png_data_uri(image)}" width="{w}" height="{h}" alt="{_esc(alt)}">'


def _display_factor(width: int) -> float:
    """Display scale for an image ``width`` pixels wide: down to :data:`_MAX_WIDTH`, small ones enlarged by an
    integer factor towards :data:`_MIN_WIDTH`."""
    if width > _MAX_WIDTH:
        return _MAX_WIDTH / width
    if width < _MIN_WIDTH:
        return float(max(1, min(_MIN_WIDTH // max(width, 1), _MAX_WIDTH // max(width, 1))))
    return 1.0


def _resize(image: np.ndarray, factor: float) -> np.ndarray:
    """Image scaled by ``factor`` (area averaging down, nearest neighbour up, so that pixels stay visible)."""
    if factor == 1.0:
        return image.copy()
    h, w = image.shape[:2]
    size = (max(1, int(round(w * factor))), max(1, int(round(h * factor))))
    return cv2.resize(image, size, interpolation=cv2.INTER_AREA if factor < 1 else cv2.INTER_NEAREST)


def _to_display(p: np.ndarray, factor: float) -> np.ndarray:
    """Pixel position (origin at the centre of the top-left pixel) in an image scaled by ``factor``."""
    return (np.asarray(p, np.float64) + 0.5) * factor - 0.5


_SHIFT = 4                                   # sub-pixel bits of OpenCV's drawing


def _fixed(p) -> tuple[int, int]:
    return int(round(p[0] * (1 << _SHIFT))), int(round(p[1] * (1 << _SHIFT)))


def _cross(img: np.ndarray, p: np.ndarray, size: float, colour, gap: float = 0.0) -> None:
    """Draw a '+' at a sub-pixel position, arms from ``gap`` to ``size`` (a gap leaves the centre visible)."""
    for ux, uy in ((1.0, 0.0), (-1.0, 0.0), (0.0, 1.0), (0.0, -1.0)):
        a, b = (p[0] + gap * ux, p[1] + gap * uy), (p[0] + size * ux, p[1] + size * uy)
        cv2.line(img, _fixed(a), _fixed(b), colour, 1, cv2.LINE_AA, _SHIFT)


def _circle(img: np.ndarray, p: np.ndarray, radius: float, colour) -> None:
    """Draw a circle outline at a sub-pixel position."""
    cv2.circle(img, _fixed(p), int(round(radius * (1 << _SHIFT))), colour, 1, cv2.LINE_AA, _SHIFT)


def _tone_map_codes(raw: np.ndarray, levels: int, gamma: float = 0.5) -> np.ndarray:
    """Raw camera codes of bright spots on a dark background -> grey display image.

    The channels are averaged; the black point is set just above the background (its median plus 4 noise
    sigmas), so that the noise neither shows nor bloats the PNG; the 99.9th percentile is full brightness.

    Args:
        raw: (H, W, 3) or (H, W) integer codes, full scale ``levels``.
        levels: full-scale code.
        gamma: display exponent (0.5 lifts the spots' faint skirts).

    Returns:
        (H, W, 3) uint8 RGB (grey).
    """
    x = np.asarray(raw, np.float32) / np.float32(max(levels, 1))
    grey = x.mean(axis=2) if x.ndim == 3 else x
    sample = grey[::max(1, grey.shape[0] // 256), ::max(1, grey.shape[1] // 256)]
    med = float(np.median(sample))
    black = med + 4 * 1.4826 * float(np.median(np.abs(sample - med)))
    peak = float(np.percentile(sample, 99.9))
    t = np.clip((grey - black) / max(peak - black, 1e-6), 0.0, 1.0) ** gamma
    return np.repeat(np.round(255 * t).astype(np.uint8)[..., None], 3, axis=2)


def _linear_display(image: np.ndarray) -> np.ndarray:
    """(H, W, 3) linear radiance -> display image (sRGB, 99.5th percentile at 0.9), scaled for display."""
    img = np.clip(np.nan_to_num(np.asarray(image, np.float64)), 0.0, None)
    level = float(np.percentile(img, 99.5))
    disp = to_display(img, 0.9 / level if level > 0 else 1.0)
    return _resize(disp, _display_factor(disp.shape[1]))


def _colormap_lut(colormap: int) -> np.ndarray:
    """(256, 3) uint8 RGB table of one of OpenCV's colour maps."""
    lut = cv2.applyColorMap(np.arange(256, dtype=np.uint8).reshape(256, 1), colormap)
    return lut.reshape(256, 3)[:, ::-1].copy()


def _diverging_lut() -> np.ndarray:
    """(256, 3) uint8 RGB blue - white - red table (for signed quantities)."""
    anchors = np.array([[33, 102, 172], [146, 197, 222], [247, 247, 247], [244, 165, 130], [178, 24, 43]], float)
    t = np.linspace(0.0, 1.0, 256)
    pos = np.linspace(0.0, 1.0, len(anchors))
    return np.stack([np.interp(t, pos, anchors[:, c]) for c in range(3)], 1).round().astype(np.uint8)


def _false_colour(values: np.ndarray, lo: float, hi: float, lut: np.ndarray) -> np.ndarray:
    """(H, W) values -> (H, W, 3) uint8 RGB through a colour table (``cv2.applyColorMap``); NaN grey."""
    v = np.asarray(values, np.float64)
    t = (v - lo) / (hi - lo) if hi > lo else np.zeros_like(v)
    idx = np.round(255 * np.clip(np.nan_to_num(t, nan=0.0), 0.0, 1.0)).astype(np.uint8)
    bgr = np.ascontiguousarray(lut[:, ::-1]).reshape(256, 1, 3)
    out = cv2.applyColorMap(idx, bgr)[..., ::-1].copy()
    out[~np.isfinite(v)] = 128
    return out


def _apply_homography(H: np.ndarray, xy: np.ndarray) -> np.ndarray:
    """(N, 2) points through a (3, 3) homography."""
    h = np.concatenate([xy, np.ones((len(xy), 1))], 1) @ np.asarray(H, np.float64).T
    return h[:, :2] / h[:, 2:3]


def _homography_jacobian(H: np.ndarray, p: np.ndarray) -> np.ndarray:
    """(2, 2) derivative of a homography at point p."""
    w = H[2, 0] * p[0] + H[2, 1] * p[1] + H[2, 2]
    q = _apply_homography(H, p[None])[0]
    return (H[:2, :2] - q[:, None] * H[2:3, :2]) / w


# ---- SVG helpers --------------------------------------------------------------------------------------------------
@dataclass
class _Series:
    """One data series of a plot: ``style`` "line" (polyline) or "dots"; ``label`` None: not in the legend."""

    x: np.ndarray
    y: np.ndarray
    colour: str
    label: str | None
    style: str = "line"
    radius: float = 1.8


@dataclass
class _Frame:
    """A plot's geometry: data limits and the plotting area in SVG units (y up, or down for image plots)."""

    xlim: tuple[float, float]
    ylim: tuple[float, float]
    width: float = 460.0
    height: float = 310.0
    left: float = 64.0
    right: float = 16.0
    top: float = 30.0
    bottom: float = 46.0
    y_down: bool = False

    @property
    def plot_width(self) -> float:
        return self.width - self.left - self.right

    @property
    def plot_height(self) -> float:
        return self.height - self.top - self.bottom

    def x(self, v):
        x0, x1 = self.xlim
        return self.left + (np.asarray(v, np.float64) - x0) / (x1 - x0) * self.plot_width

    def y(self, v):
        y0, y1 = self.ylim
        t = (np.asarray(v, np.float64) - y0) / (y1 - y0)
        return self.top + (t if self.y_down else 1.0 - t) * self.plot_height

    def axes(self, xlabel: str, ylabel: str, title: str, ticks: int = 5) -> list[str]:
        """Frame, ticks with labels, axis labels and title (SVG elements)."""
        L, T, W, H = self.left, self.top, self.plot_width, self.plot_height
        out = [f'<rect x="{L:.1f}" y="{T:.1f}" width="{W:.1f}" height="{H:.1f}" fill="white" stroke="#444"/>']
        for v in _nice_ticks(*self.xlim, ticks):
            x = float(self.x(v))
            out.append(f'<line x1="{x:.1f}" y1="{T:.1f}" x2="{x:.1f}" y2="{T + H:.1f}" stroke="#e6e6e6"/>')
            out.append(f'<line x1="{x:.1f}" y1="{T + H:.1f}" x2="{x:.1f}" y2="{T + H + 4:.1f}" stroke="#444"/>')
            out.append(f'<text x="{x:.1f}" y="{T + H + 16:.1f}" text-anchor="middle">{_tick_label(v)}</text>')
        for v in _nice_ticks(*sorted(self.ylim), ticks):
            y = float(self.y(v))
            out.append(f'<line x1="{L:.1f}" y1="{y:.1f}" x2="{L + W:.1f}" y2="{y:.1f}" stroke="#e6e6e6"/>')
            out.append(f'<line x1="{L - 4:.1f}" y1="{y:.1f}" x2="{L:.1f}" y2="{y:.1f}" stroke="#444"/>')
            out.append(f'<text x="{L - 7:.1f}" y="{y + 4:.1f}" text-anchor="end">{_tick_label(v)}</text>')
        out.append(f'<rect x="{L:.1f}" y="{T:.1f}" width="{W:.1f}" height="{H:.1f}" fill="none" stroke="#444"/>')
        out.append(f'<text x="{L + W / 2:.1f}" y="{self.height - 8:.1f}" text-anchor="middle">{_esc(xlabel)}</text>')
        out.append(f'<text transform="translate(14 {T + H / 2:.1f}) rotate(-90)" text-anchor="middle">'
                   f'{_esc(ylabel)}</text>')
        if title:
            out.append(f'<text x="{L + W / 2:.1f}" y="{T - 10:.1f}" text-anchor="middle" font-weight="bold">'
                       f'{_esc(title)}</text>')
        return out

    def clip(self, ident: str) -> str:
        return (f'<clipPath id="{ident}"><rect x="{self.left:.1f}" y="{self.top:.1f}" '
                f'width="{self.plot_width:.1f}" height="{self.plot_height:.1f}"/></clipPath>')


_svg_ids = itertools.count(1)            # unique clip-path ids within a document


def _svg(width: float, height: float, elements: list[str], label: str) -> str:
    """A complete inline ``<svg>`` element."""
    return (f'<svg xmlns="http://www.w3.org/2000/svg" width="{width:.0f}" height="{height:.0f}" '
            f'viewBox="0 0 {width:.0f} {height:.0f}" font-family="sans-serif" font-size="11" role="img" '
            f'aria-label="{_esc(label)}">\n' + "\n".join(elements) + "\n</svg>")


def _points(xs, ys) -> str:
    return " ".join(f"{x:.1f},{y:.1f}" for x, y in zip(np.ravel(xs), np.ravel(ys)))


def _svg_legend(frame: _Frame, entries: list[tuple[str, str, str]]) -> list[str]:
    """Legend box at the plot's top-left: entries (label, colour, style)."""
    if not entries:
        return []
    x, y = frame.left + 8, frame.top + 8
    width = 34 + 6.2 * max(len(e[0]) for e in entries)
    out = [f'<rect x="{x:.1f}" y="{y:.1f}" width="{width:.1f}" height="{16 * len(entries) + 6:.1f}" '
           f'fill="white" fill-opacity="0.85" stroke="#bbb"/>']
    for i, (label, colour, style) in enumerate(entries):
        cy = y + 12 + 16 * i
        if style == "dots":
            out.append(f'<circle cx="{x + 15:.1f}" cy="{cy:.1f}" r="2.5" fill="{colour}"/>')
        else:
            out.append(f'<line x1="{x + 6:.1f}" y1="{cy:.1f}" x2="{x + 24:.1f}" y2="{cy:.1f}" stroke="{colour}" '
                       f'stroke-width="2"/>')
        out.append(f'<text x="{x + 30:.1f}" y="{cy + 4:.1f}">{_esc(label)}</text>')
    return out


def _svg_line_plot(series: list[_Series], *, xlabel: str, ylabel: str, title: str,
                   xlim: tuple[float, float] | None = None, ylim: tuple[float, float] | None = None) -> str:
    """A line/scatter plot with axes, ticks, labels and a legend.

    Args:
        series: the data (lines drawn as polylines, dots as small circles).
        xlabel, ylabel, title: texts.
        xlim, ylim: data limits; None: the data's range.

    Returns:
        ``<svg>`` text.
    """
    xs = np.concatenate([np.ravel(s.x) for s in series]) if series else np.zeros(1)
    ys = np.concatenate([np.ravel(s.y) for s in series]) if series else np.zeros(1)
    frame = _Frame(xlim or _data_range(xs), ylim or _data_range(ys))
    ident = f"clip{next(_svg_ids)}"
    out = [frame.clip(ident), *frame.axes(xlabel, ylabel, title), f'<g clip-path="url(#{ident})">']
    legend = []
    for s in sorted(series, key=lambda s: s.style == "dots"):           # dots over lines
        x, y = frame.x(s.x), frame.y(s.y)
        if s.style == "dots":
            outline = ' stroke="#222" stroke-width="0.6"' if s.radius > 2.5 else ""
            out.append(f'<g fill="{s.colour}" fill-opacity="0.6"{outline}>' + "".join(
                f'<circle cx="{a:.1f}" cy="{b:.1f}" r="{s.radius:g}"/>' for a, b in zip(x, y)) + "</g>")
        else:
            out.append(f'<polyline fill="none" stroke="{s.colour}" stroke-width="1.3" points="{_points(x, y)}"/>')
        if s.label:
            legend.append((s.label, s.colour, s.style))
    out.append("</g>")
    out += _svg_legend(frame, legend)
    return _svg(frame.width, frame.height, out, title)


def _svg_histogram(values: np.ndarray, *, xlabel: str, title: str, colour: str, bins: int | None = None) -> str:
    """Histogram of values (bars).

    Args:
        values: (N,) numbers.
        xlabel, title: texts.
        colour: bar colour.
        bins: number of bins; None: about sqrt(N), 5 to 40.

    Returns:
        ``<svg>`` text.
    """
    v = np.asarray(values, np.float64)
    v = v[np.isfinite(v)]
    if v.size == 0:
        raise ValueError("no values to plot")
    bins = bins or int(np.clip(round(math.sqrt(v.size)), 5, 40))
    lo, hi = _data_range(v, pad=0.0)
    counts, edges = np.histogram(v, bins=bins, range=(lo, hi))
    frame = _Frame((float(edges[0]), float(edges[-1])), (0.0, float(max(counts.max(), 1)) * 1.08))
    out = frame.axes(xlabel, "lenslets", title)
    y0 = float(frame.y(0.0))
    for n, a, b in zip(counts, edges[:-1], edges[1:]):
        if n:
            xa, xb, yn = float(frame.x(a)), float(frame.x(b)), float(frame.y(n))
            out.append(f'<rect x="{xa:.1f}" y="{yn:.1f}" width="{max(xb - xa - 0.6, 0.5):.1f}" '
                       f'height="{y0 - yn:.1f}" fill="{colour}"/>')
    med = float(np.median(v))
    xm = float(frame.x(med))
    out.append(f'<line x1="{xm:.1f}" y1="{frame.top:.1f}" x2="{xm:.1f}" y2="{y0:.1f}" stroke="#222" '
               f'stroke-dasharray="4 3"/>')
    out += _svg_legend(frame, [(f"median {med:.4g}, N = {v.size}", "#222", "line")])
    return _svg(frame.width, frame.height, out, title)


def _image_frame(shape: tuple[int, int], width: float = 520.0, right: float = 16.0, top: float = 30.0) -> _Frame:
    """A frame in image pixels (y down), its plot area with the image's aspect ratio."""
    h, w = shape
    frame = _Frame((-0.5, w - 0.5), (-0.5, h - 0.5), width=width, right=right, y_down=True, top=top, bottom=42)
    frame.height = frame.top + frame.bottom + frame.plot_width * h / w
    return frame


def _svg_quiver(points: np.ndarray, vectors: np.ndarray, magnification: float, image_shape: tuple[int, int],
                bar: float, unit: str, *, title: str) -> str:
    """Arrows at points in an image, their lengths magnified, with a scale bar.

    Args:
        points: (N, 2) pixel positions (x, y).
        vectors: (N, 2) the arrows, in the same pixels (before magnification).
        magnification: factor on the arrows' lengths.
        image_shape: (H, W) of the image.
        bar: the scale bar's length, in the arrows' units.
        unit: text after the scale bar's length.
        title: plot title.

    Returns:
        ``<svg>`` text.
    """
    frame = _image_frame(image_shape, top=46.0)
    out = frame.axes("x (px)", "y (px)", "")
    out.append(f'<text x="{frame.left:.1f}" y="{frame.top - 26:.1f}" font-weight="bold">{_esc(title)}</text>')
    px_per_unit = frame.plot_width / (frame.xlim[1] - frame.xlim[0])
    arrows = []
    for p, v in zip(np.asarray(points, np.float64), np.asarray(vectors, np.float64)):
        x0, y0 = float(frame.x(p[0])), float(frame.y(p[1]))
        dx, dy = v * magnification * px_per_unit
        arrows.append(f'<circle cx="{x0:.1f}" cy="{y0:.1f}" r="1.3" fill="#555"/>')
        arrows.append(_svg_arrow(x0, y0, x0 + dx, y0 + dy, "#c0392b"))
    out.append("<g>" + "".join(arrows) + "</g>")
    length = bar * magnification * px_per_unit                 # scale bar, top right above the plot
    bx1, by = frame.left + frame.plot_width, frame.top - 12
    out.append(_svg_arrow(bx1 - length, by, bx1, by, "#c0392b"))
    out.append(f'<text x="{bx1 - length - 6:.1f}" y="{by + 4:.1f}" text-anchor="end">{_fmt_plain(bar)} {unit}'
               f'</text>')
    return _svg(frame.width, frame.height, out, title)


def _svg_arrow(x0: float, y0: float, x1: float, y1: float, colour: str) -> str:
    """An arrow (line and filled head) from (x0, y0) to (x1, y1)."""
    d = math.hypot(x1 - x0, y1 - y0)
    line = f'<line x1="{x0:.1f}" y1="{y0:.1f}" x2="{x1:.1f}" y2="{y1:.1f}" stroke="{colour}" stroke-width="1.2"/>'
    if d < 1e-6:
        return line
    ux, uy = (x1 - x0) / d, (y1 - y0) / d
    head = min(5.0, 0.45 * d)
    a = (x1 - head * ux + 0.5 * head * uy, y1 - head * uy - 0.5 * head * ux)
    b = (x1 - head * ux - 0.5 * head * uy, y1 - head * uy + 0.5 * head * ux)
    return line + f'<polygon points="{x1:.1f},{y1:.1f} {a[0]:.1f},{a[1]:.1f} {b[0]:.1f},{b[1]:.1f}" fill="{colour}"/>'


def _svg_cell_map(cells: np.ndarray, values: np.ndarray, valid: np.ndarray, image_shape: tuple[int, int], *,
                  label: str, title: str) -> str:
    """Polygons (lenslet cells) in an image, coloured by a value, with a colour bar.

    Args:
        cells: (K, V, 2) polygon vertices, pixels.
        values: (K,) the value per cell.
        valid: (K,) False: drawn grey.
        image_shape: (H, W) of the image.
        label: colour bar label.
        title: plot title.

    Returns:
        ``<svg>`` text.
    """
    frame = _image_frame(image_shape, width=600.0, right=96.0)
    out = frame.axes("x (px)", "y (px)", title)
    lut = _colormap_lut(cv2.COLORMAP_VIRIDIS)
    v = np.asarray(values, np.float64)
    ok = np.asarray(valid, bool) & np.isfinite(v)
    lo, hi = (float(v[ok].min()), float(v[ok].max())) if ok.any() else (0.0, 1.0)
    ident = f"clip{next(_svg_ids)}"
    out.insert(0, frame.clip(ident))
    polys = []
    for poly, val, good in zip(np.asarray(cells, np.float64), v, ok):
        fill = _hex_colour(lut[_lut_index(val, lo, hi)]) if good else "#bbbbbb"
        polys.append(f'<polygon points="{_points(frame.x(poly[:, 0]), frame.y(poly[:, 1]))}" fill="{fill}" '
                     f'stroke="white" stroke-width="0.6"/>')
    out.append(f'<g clip-path="url(#{ident})">' + "".join(polys) + "</g>")
    out += _colour_bar_elements(frame.left + frame.plot_width + 14, frame.top, 14, frame.plot_height, lo, hi, lut,
                                label)
    return _svg(frame.width, frame.height, out, title)


def _colour_bar_elements(x: float, y: float, w: float, h: float, lo: float, hi: float, lut: np.ndarray,
                         label: str, steps: int = 64) -> list[str]:
    """A vertical colour bar (``steps`` bands, ``hi`` on top) with ticks and a label (SVG elements)."""
    out = []
    band = h / steps
    for i in range(steps):
        t = (i + 0.5) / steps
        colour = _hex_colour(lut[int(round(255 * (1 - t)))])
        out.append(f'<rect x="{x:.1f}" y="{y + i * band:.2f}" width="{w:.1f}" height="{band + 0.3:.2f}" '
                   f'fill="{colour}" shape-rendering="crispEdges"/>')
    out.append(f'<rect x="{x:.1f}" y="{y:.1f}" width="{w:.1f}" height="{h:.1f}" fill="none" stroke="#444"/>')
    span = hi - lo if hi > lo else 1.0
    for v in _nice_ticks(lo, hi if hi > lo else lo + 1.0, 5):
        ty = y + (1 - (v - lo) / span) * h
        out.append(f'<line x1="{x + w:.1f}" y1="{ty:.1f}" x2="{x + w + 4:.1f}" y2="{ty:.1f}" stroke="#444"/>')
        out.append(f'<text x="{x + w + 6:.1f}" y="{ty + 4:.1f}">{_tick_label(v)}</text>')
    out.append(f'<text x="{x:.1f}" y="{y - 8:.1f}">{_esc(label)}</text>')
    return out


def _svg_colour_bar(lo: float, hi: float, lut: np.ndarray, label: str, height: float = 260.0) -> str:
    """A standalone vertical colour bar (``<svg>`` text) to put beside a false-colour picture."""
    elements = _colour_bar_elements(8, 24, 16, height, lo, hi, lut, label)
    return _svg(max(90.0, 6.5 * len(label) + 12), height + 36, elements, f"colour bar: {label}")


# ---- HTML helpers -------------------------------------------------------------------------------------------------
def _esc(text) -> str:
    return html.escape(str(text), quote=True)


def _explain(text: str) -> str:
    return f'<p class="explain">{_esc(text)}</p>\n'


def _figure(content: str, caption: str) -> str:
    """``<figure>`` with already-formatted content and a plain-text caption."""
    return f"<figure>{content}<figcaption>{_esc(caption)}</figcaption></figure>"


def _figs(items: list[str]) -> str:
    """Figures side by side, wrapping."""
    return '<div class="figs">\n' + "\n".join(i for i in items if i) + "\n</div>\n"


def _table(head: tuple[str, ...], rows, *, numeric: tuple[int, ...] = (), header: bool = True) -> str:
    """HTML table of plain-text cells; columns in ``numeric`` right-aligned in a monospace font."""
    lines = ["<table>"]
    if header:
        lines.append("<tr>" + "".join(f"<th>{_esc(h)}</th>" for h in head) + "</tr>")
    for row in rows:
        lines.append("<tr>" + "".join(f'<td class="num">{_esc(c)}</td>' if i in numeric else f"<td>{_esc(c)}</td>"
                                      for i, c in enumerate(row)) + "</tr>")
    lines.append("</table>")
    return "\n".join(lines)


def _heatmap_table(matrix: np.ndarray, row_labels: list[str], col_labels: list[str], digits: int = 4) -> str:
    """A matrix as a table whose cells are coloured by |value| (white to dark blue), values written in them.

    Args:
        matrix: (R, C) numbers.
        row_labels, col_labels: R and C labels.
        digits: decimals shown.

    Returns:
        ``<table>`` text.
    """
    m = np.asarray(matrix, np.float64)
    top = float(np.max(np.abs(m))) or 1.0
    lines = ["<table>", "<tr><th></th>" + "".join(f"<th>{_esc(c)}</th>" for c in col_labels) + "</tr>"]
    for label, row in zip(row_labels, m):
        cells = []
        for v in row:
            t = abs(v) / top
            rgb = np.array([255, 255, 255]) * (1 - t) + np.array([8, 48, 107]) * t
            text = "white" if t > 0.5 else "#111"
            cells.append(f'<td class="heat" style="background:{_hex_colour(rgb)};color:{text}">{v:.{digits}f}</td>')
        lines.append(f"<tr><th>{_esc(label)}</th>" + "".join(cells) + "</tr>")
    lines.append("</table>")
    return "\n".join(lines)


def _guarded(build, what: str) -> str:
    """``build()``, or a note where a malformed diagnostic keeps it from being drawn."""
    try:
        return build()
    except (KeyError, IndexError, TypeError, ValueError, AttributeError, ZeroDivisionError, cv2.error,
            np.linalg.LinAlgError) as exc:
        return f'<p class="note">{_esc(what)}: left out ({_esc(type(exc).__name__)}: {_esc(exc)}).</p>'


# ---- numbers ------------------------------------------------------------------------------------------------------
def _num(v, fmt: str) -> str:
    """A number formatted, or "n/a" for NaN/None."""
    try:
        v = float(v)
    except (TypeError, ValueError):
        return "n/a"
    return format(v, fmt) if math.isfinite(v) else "n/a"


def _vec(values, fmt: str) -> str:
    return "(" + ", ".join(_num(v, fmt) for v in np.ravel(np.asarray(values, np.float64))) + ")"


def _fmt_plain(v: float) -> str:
    """A 1-2-5 number without trailing zeros (e.g. ``2000``, ``0.005``)."""
    return f"{v:.6g}"


def _hex_colour(rgb) -> str:
    r, g, b = (int(np.clip(round(float(c)), 0, 255)) for c in rgb)
    return f"#{r:02x}{g:02x}{b:02x}"


def _lut_index(v: float, lo: float, hi: float) -> int:
    return int(round(255 * min(max((v - lo) / (hi - lo), 0.0), 1.0))) if hi > lo else 128


def _data_range(v: np.ndarray, pad: float = 0.04) -> tuple[float, float]:
    """Finite range of values, padded by a fraction of its span (a tiny span is widened)."""
    v = np.asarray(v, np.float64)
    v = v[np.isfinite(v)]
    if v.size == 0:
        return 0.0, 1.0
    lo, hi = float(v.min()), float(v.max())
    if hi - lo <= 1e-12 * max(1.0, abs(lo)):
        d = 0.5 * abs(lo) if lo != 0 else 0.5
        return lo - d, hi + d
    d = pad * (hi - lo)
    return lo - d, hi + d


def _nice_floor(v: float) -> float:
    """Largest 1, 2 or 5 times a power of ten not above v (v > 0)."""
    e = math.floor(math.log10(v))
    for m in (5.0, 2.0, 1.0):
        if m * 10.0 ** e <= v:
            return m * 10.0 ** e
    return 10.0 ** e


def _nice_ticks(lo: float, hi: float, count: int = 5) -> list[float]:
    """About ``count`` round tick values (1, 2, 2.5 or 5 times a power of ten apart) within [lo, hi]."""
    if not (math.isfinite(lo) and math.isfinite(hi)) or hi <= lo:
        return [lo] if math.isfinite(lo) else []
    raw = (hi - lo) / max(count, 1)
    mag = 10.0 ** math.floor(math.log10(raw))
    step = next(m * mag for m in (1.0, 2.0, 2.5, 5.0, 10.0) if m * mag >= raw)
    first = math.ceil(lo / step - 1e-9)
    ticks = []
    i = first
    while i * step <= hi + 1e-9 * step:
        ticks.append(round(i * step, 12))
        i += 1
    return ticks


def _tick_label(v: float) -> str:
    """Short tick label (``0``, ``0.25``, ``-0.04``, ``2e-05``)."""
    if v == 0:
        return "0"
    if 1e-3 <= abs(v) < 1e5:
        return f"{v:.6f}".rstrip("0").rstrip(".")
    return f"{v:.3g}"

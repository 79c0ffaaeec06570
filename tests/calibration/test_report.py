"""The calibration report: one self-contained HTML file with pictures, from a real calibration of a small rig."""

from __future__ import annotations

import base64
import re
import xml.etree.ElementTree as ET
from dataclasses import replace
from html.parser import HTMLParser

import cv2
import numpy as np
import pytest

from lftransfer.reports.calibration_report import (REPORT_NAME, SECTIONS, render_calibration_report,
                                               write_calibration_report)
from lftransfer.reports.templating import environment
from lftransfer.calibration.rig import load_calibration
from lftransfer.calibration.targets import TARGETS
from lftransfer.sim.calibration_errors import calibration_errors

VOID = {"area", "base", "br", "col", "embed", "hr", "img", "input", "link", "meta", "source", "track", "wbr"}


class _NestingChecker(HTMLParser):
    """Parses a document and records every end tag that does not close the innermost open element."""

    def __init__(self) -> None:
        super().__init__()
        self.stack: list[str] = []
        self.problems: list[str] = []

    def handle_starttag(self, tag, attrs):
        if tag not in VOID:
            self.stack.append(tag)

    def handle_endtag(self, tag):
        if not self.stack or self.stack[-1] != tag:
            self.problems.append(f"</{tag}> at line {self.getpos()[0]} closes {self.stack[-1:] or 'nothing'}")
        else:
            self.stack.pop()


def _check_well_formed(text: str) -> None:
    checker = _NestingChecker()
    checker.feed(text)
    checker.close()
    assert checker.problems == [] and checker.stack == []


def _embedded(text: str) -> list[tuple[str, bytes]]:
    """Every ``<img>``'s (type, decoded data); an image that is not a base64 data URI fails."""
    sources = re.findall(r'<img src="([^"]*)"', text)
    found = [re.fullmatch(r"data:image/(png|svg\+xml);base64,([A-Za-z0-9+/=]+)", s) for s in sources]
    assert all(found), [s[:40] for s, f in zip(sources, found) if not f]
    return [(f.group(1), base64.b64decode(f.group(2))) for f in found]


@pytest.fixture(scope="module")
def calibrated(calibrated_rig, tmp_path_factory):
    """The shared calibrated rig (tests/calibration/conftest.py: hidden truth seed 3) and its report."""
    scene, rig, cal, _messages = calibrated_rig
    errors = calibration_errors(cal, rig.truth)
    path = write_calibration_report(tmp_path_factory.mktemp("report"), cal, errors)
    return scene, cal, errors.to_json(), path



def test_01_sections_pictures_and_structure(calibrated):
    """One HTML file with every section and its figures, all embedded as data URIs; nothing external."""
    _, _, _, path = calibrated
    assert path.name == REPORT_NAME and path.is_file()
    assert not [p for p in path.parent.iterdir() if p != path]              # no temporary file left behind
    text = path.read_text(encoding="utf-8")
    for i, name in enumerate(SECTIONS, 1):
        assert f'<section id="s{i}">\n<h2>{i}. {name}</h2>' in text and f'href="#s{i}"' in text
    assert "Against the simulator's hidden truth" in text
    _check_well_formed(text)
    images = _embedded(text)
    kinds = [k for k, _ in images]
    # lenslets (2), k1 and k2 histograms, k1 map, two responses, vignetting, flood-lit board, fringe phase
    assert len(images) == 10 and kinds.count("png") >= 4 and kinds.count("svg+xml") >= 5
    for kind, data in images:
        if kind == "png":
            img = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
            assert img is not None and 300 <= img.shape[1] <= 1100
        else:
            assert ET.fromstring(data).tag == "{http://www.w3.org/2000/svg}svg"
            links = re.findall(rb'href="([^"]*)"', data)
            assert all(h.startswith((b"#", b"data:")) for h in links)      # nothing fetched from within
    outside = re.sub(r'"data:image/[^"]*"', '""', text)                   # self-contained: no URL, no script
    assert "//" not in outside and "url(" not in outside and "<script" not in text and "<svg" not in text
    assert path.stat().st_size < 2_000_000
    assert "left out" not in text and "not available" not in text           # every picture was drawn


def test_02_summary_numbers(calibrated):
    """The calibration's key numbers appear as the summary writes them."""
    _, cal, _, path = calibrated
    text = path.read_text(encoding="utf-8")
    rad = cal.radiometry
    numbers = [f"{cal.model.array.pitch * 1e3:.4f}", f"{cal.lattice.pitch_px:.3f}", f"{cal.lattice.rms_px:.4f}",
               f"{cal.projector_fit.rms_px:.3f}", f"{np.degrees(cal.distortion.mount_angle):.4f}",
               f"{cal.pose.rms_px:.3f}", f"{cal.pose.scale:.6f}", f"{rad.max_radiance:.5g}",
               f"{rad.camera_exposure:.5g}", *(f"{g:.4f}" for g in rad.camera_gamma),
               *(f"{g:.4f}" for g in rad.projector_gamma), *(f"{b:.5f}" for b in rad.black_level),
               f"{cal.projector_fit.homography[0, 0]:.6g}", f"{rad.cross_talk[0, 1]:.4f}"]
    missing = [n for n in numbers if n not in text]
    assert missing == []


def test_03_truth_table_marks_each_target(calibrated):
    """Each target is marked pass or fail as the error meets it; a failing error is marked fail."""
    _, cal, errors, path = calibrated
    text = path.read_text(encoding="utf-8")
    measured = [t for t in TARGETS if t.key in errors]             # the one definition (calibration/targets.py)
    assert {"lenslet_centre_rms_px", "pose_position_max_mm", "pose_rotation_deg"} <= {t.key for t in measured}
    passes = sum(t.met(errors[t.key]) for t in measured)
    assert text.count('class="pass"') == passes
    assert text.count('class="fail"') == len(measured) - passes
    assert f"{passes} of\n{len(measured)} targets met" in text
    worse = render_calibration_report(cal, {**errors, "lenslet_centre_rms_px": 0.5})
    assert worse.count('class="fail"') == len(measured) - passes + 1
    assert "hidden truth" not in render_calibration_report(cal)


def test_04_loaded_from_file_still_renders(calibrated, tmp_path):
    """A calibration read back from its file (no fits, no diagnostics) renders, saying what is missing."""
    scene, cal, _, _ = calibrated
    loaded = load_calibration(cal.write(tmp_path / "calibration.json"), scene)
    assert loaded.lattice is None and loaded.distortion is None and loaded.projector_fit is None
    path = write_calibration_report(tmp_path / "out" / "loaded.html", loaded)
    assert path == tmp_path / "out" / "loaded.html"
    text = path.read_text(encoding="utf-8")
    assert text.count("not available (loaded from file)") >= 4
    for i, name in enumerate(SECTIONS, 1):
        assert f"<h2>{i}. {name}</h2>" in text
    assert f"{loaded.model.array.pitch * 1e3:.4f}" in text
    assert "left out" not in text
    _check_well_formed(text)
    # the same with every fit and diagnostic dropped from the calibration in memory
    bare = replace(cal, lattice=None, distortion=None, projector_fit=None, diagnostics={})
    _check_well_formed(render_calibration_report(bare))


def test_05_missing_or_malformed_diagnostics_skip_pictures(calibrated):
    """A missing or malformed diagnostic leaves its picture out; the report is still written."""
    _, cal, _, _ = calibrated
    odd = replace(cal, diagnostics={"collimated": "not an image", "exposure": 3,
                                    "pose": {"images": {"pattern": None}, "normalised": np.zeros(3),
                                             "found": None}},
                  radiometry=replace(cal.radiometry, diagnostics={"camera_response_samples": [[1, 2, 3]],
                                                                  "vignetting_fit": "?"}))
    text = render_calibration_report(odd)
    _check_well_formed(text)
    for what in ("collimated image", "corners", "camera response"):
        assert f"{what}: left out (" in text
    assert text.count("left out") == 3
    for i, name in enumerate(SECTIONS, 1):
        assert f"<h2>{i}. {name}</h2>" in text
    # a calibration whose section cannot be computed at all: that section says so, the others stand
    broken = replace(cal, pose=None)
    text = render_calibration_report(broken)
    _check_well_formed(text)
    assert "section Global pose: left out (AttributeError" in text and "<h2>6. Global pose</h2>" in text


def test_06_autoescaped(calibrated):
    """Text from the data is escaped by the template (a script in an error's name stays text)."""
    _, cal, errors, _ = calibrated
    text = render_calibration_report(cal, {**errors, "<script>alert('x')</script> & more": 1.5})
    assert "<script" not in text
    assert "&lt;script&gt;alert(&#39;x&#39;)&lt;/script&gt; &amp; more" in text
    _check_well_formed(text)
    env = environment()
    assert env.autoescape("calibration_report.html") and env.autoescape("base.html")


def test_07_base_template_serves_other_reports():
    """The shared layout (base.html) and building blocks (macros.html) make another report's page."""
    page = environment().from_string(
        '{% extends "base.html" %}{% import "macros.html" as m %}{% block content %}'
        '{% call m.section(1, "Runs", {}) %}{{ m.table(("a", "b"), rows, numeric=(1,)) }}'
        '{{ m.figure({"note": "<b>none</b>"}) }}{% endcall %}{% endblock %}'
    ).render(title="Run <report>", sections=("Runs",), rows=[("x < y", "1.5")])
    _check_well_formed(page)
    assert "<title>Run &lt;report&gt;</title>" in page and '<td class="num">1.5</td>' in page
    assert "<td>x &lt; y</td>" in page and "&lt;b&gt;none&lt;/b&gt;" in page and '<a href="#s1">' in page

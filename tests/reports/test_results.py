"""docs/results.md is generated from the stored runs' JSON (``make results``): the values, the provenance and the
command that reproduces each table; a missing run says so; a malformed file is one error naming it and the field."""

from __future__ import annotations

import json

import pytest

from lftransfer.reports.results import NOT_STORED, RUN_BY_NAME, ResultsError, load_store, main, render_results

PROVENANCE = {"commands": ["lft demo --quick --out out/runs/demo_quick"], "commit": "0123abcd4567ef", "dirty": False,
              "date": "2031-02-03 04:05 UTC",
              "machine": {"cpus": 7, "platform": "Linux-test-x86_64", "load_average": [0.25, 0.5, 0.75]},
              "wall_s": 123.4}


def demo_data(**over) -> dict:
    m = lambda c, p, o: {"cross_transfer_rel_error": c, "psnr_db": p, "psnr_objects_db": o}  # noqa: E731
    data = {**m(0.1234, 61.234, 52.346), "psnr_db_direct_only": 50.5, "gt_noise_psnr_db": 77.7,
            "cross_gt_noise_rel": 0.0321, "lighting_model": "area", "reconstruction": "linear",
            "projection": "depth", "window": "edge",
            "by_lighting_model": {"area": m(0.1234, 61.234, 52.346), "point": m(0.2222, 60.0, 51.0)},
            "by_window": {"edge": m(0.1234, 61.234, 52.346), "cut": m(0.1556, 60.5, 51.5)},
            "negative_control": {"rig_model": "nominal (rig file)", "cross_transfer_rel_error": 0.5432,
                                 "psnr_objects_db": 44.4, "cross_error_margin": 0.4198,
                                 "psnr_objects_margin_db": 7.945, "measurably_worse": True},
            "cross_by_side": {"real": {"rel_error": 0.1417, "energy_ratio": 0.96, "rel_error_shape": 0.14,
                                       "gt_noise_rel": 0.03, "pixels": 3284}},
            "bounces": [{"index": 0, "real_energy": 0.0056, "synthetic_energy": 0.0043, "projector_gain": None}],
            "calibration_errors": {"pose_position_rms_mm": 0.1876},
            "timings_s": {"calibration": 401.25, "total": 706.5},
            "resolution": {"lenslets": [10, 12], "lattice": "hex", "lf_camera": [512, 384], "projector": [256, 192],
                           "view": [256, 192], "angular_samples": 16}}
    data.update(over)
    return data


def write(folder, name, kind, data, provenance=PROVENANCE):
    folder.mkdir(parents=True, exist_ok=True)
    (folder / f"{name}.json").write_text(json.dumps({"run": name, "kind": kind, "provenance": provenance,
                                                     "data": data}))


def test_01_values_provenance_and_the_command(tmp_path):
    store = tmp_path / "runs"
    write(store, "demo_quick", "demo", demo_data())
    md = render_results(load_store(store))
    section = md.split("### Fig. 4 at quarter resolution")[1].split("\n### ")[0]
    # the values, as the run wrote them
    for text in ("0.123", "61.23 dB", "52.35 dB", "0.222", "0.156", "nominal (rig file)", "0.543", "0.420",
                 "7.95 dB", "0.142", "0.188", "401.25", "706.50", "10 x 12 hex lenslets"):
        assert text in section, text
    # the provenance: command, commit, date, machine (CPUs, platform, load), wall time
    assert "Reproduce: `lft demo --quick --out out/runs/demo_quick`" in section
    assert "scripts/store_runs.py demo_quick" in section
    for text in ("0123abcd4567ef", "2031-02-03 04:05 UTC", "7 CPUs", "Linux-test-x86_64", "0.25 / 0.50 / 0.75",
                 "wall time 123 s"):
        assert text in section, text
    assert "uncommitted" not in section


def test_02_a_missing_run_is_not_invented(tmp_path):
    store = tmp_path / "runs"
    write(store, "demo_quick", "demo", demo_data())
    md = render_results(load_store(store))
    section = md.split("### Fig. 4 at the paper's resolution (`lft demo`)")[1].split("\n### ")[0]
    assert NOT_STORED in section
    assert RUN_BY_NAME["demo"].command_line in section
    assert "|" not in section                      # no table
    # every registered run without a file says so; an empty store gives only those lines
    md = render_results(load_store(tmp_path))
    assert md.count(NOT_STORED) == len(RUN_BY_NAME)


@pytest.mark.parametrize("drop, field", [
    (("data", "psnr_objects_db"), "data.psnr_objects_db"),
    (("provenance", "commit"), "provenance.commit"),
    (("data", "negative_control", "rig_model"), "data.negative_control.rig_model"),
])
def test_03_a_missing_field_names_the_file_and_the_field(tmp_path, drop, field):
    store = tmp_path / "runs"
    write(store, "demo_quick", "demo", demo_data())
    path = store / "demo_quick.json"
    raw = json.loads(path.read_text())
    node = raw
    for key in drop[:-1]:
        node = node[key]
    del node[drop[-1]]
    path.write_text(json.dumps(raw))
    with pytest.raises(ResultsError) as err:
        render_results(load_store(store))
    assert str(path) in str(err.value) and f"'{field}'" in str(err.value)


def test_04_not_json_and_the_command_line(tmp_path, capsys):
    store = tmp_path / "runs"
    write(store, "bench_quick", "bench", {"pipeline_iteration_ms": 16.25})
    assert main([str(store), str(tmp_path / "results.md")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and "bench_quick.json" in err and "'data.pipeline_fps'" in err
    (store / "bench_quick.json").write_text("{ not json")
    assert main([str(store), str(tmp_path / "results.md")]) == 2
    assert "bench_quick.json: not valid JSON" in capsys.readouterr().err
    assert not (tmp_path / "results.md").exists()


def test_05_every_kind_renders(tmp_path):
    store = tmp_path / "runs"
    spread = lambda x: {"median": x, "min": x - 1, "max": x + 1, "stdev": 0.5}  # noqa: E731
    write(store, "bench_quick", "bench", {
        "pipeline_iteration_ms": 16.25, "pipeline_iteration": spread(16.25), "pipeline_fps": 61.5, "step_fps": 3.7,
        "stages_ms": {"encode": spread(0.8), "incident_light": spread(2.5)}, "capture_ms": 232.0,
        "rig_stages_ms": {"capture_lf": spread(197.0)}, "unstaged_ms": 1.5, "floor_ms": 1.7,
        "floor": {"rays": [122880, 196608]}, "iteration_over_floor": 9.56,
        "fast_vs_exact": {"psnr_db": 76.31, "psnr_objects_db": 64.02}, "peer": None, "peak_rss_mb": 452.0,
        "settings": {"resolution": {"lenslets": [10, 12], "lattice": "hex", "lf_camera": [512, 384],
                                    "projector": [256, 192], "view": [256, 192]}, "angular_samples": 16}})
    write(store, "fig6_quick", "sequence", {
        "report": {"mode": "live", "summary": {"frames": 48, "cross_transfer_rel_error_max": 0.6412},
                   "frames": [{"index": 6, "time_s": 0.25, "metrics": {"psnr_objects_db": 30.71,
                                                                       "cross_transfer_rel_error": 0.6123}},
                              {"index": 7, "time_s": 0.29, "metrics": None}]},
        "effect": {"kind": "reflection", "on": "bowl", "by": "photo", "agreement_bound": 0.2,
                   "worst_relative_error": {"added_radiance": 0.1612}, "same_trend": {"added_radiance": 1.0},
                   "points": [{"index": 6, "time_s": 0.25, "distance_m": 0.2651,
                               "transfer": {"added_radiance": 0.00871}, "truth": {"added_radiance": 0.00872}}]}})
    write(store, "calibration_seeds", "calibration_seeds", {
        "seeds": {"1": {"pose_position_rms_mm": 0.391}, "2": {"pose_position_rms_mm": 0.2}},
        "summary": {"pose_position_rms_mm": {"worst": 0.391, "mean": 0.3, "target": 1.0, "met": True}}})
    write(store, "twin_compare", "twin_compare", {
        "scene": "fig4", "quick": True, "gt_spp": 4096, "live_frames": 10,
        "inproc": {"cross_transfer_rel_error": 0.1564, "psnr_objects_db": 37.03},
        "hardware": {"cross_transfer_rel_error": 0.1432, "psnr_objects_db": 39.9},
        "latency": [{"configured_ms": 60, "median_ms": 173.6}]},
        provenance={**PROVENANCE, "machine": "x86_64, vm", "wall_s": None, "dirty": True})
    side = lambda e, r: {"real": {"rel_error": r, "energy_ratio": 0.3}, "synthetic": {"rel_error": e}}  # noqa: E731
    write(store, "probe_quick", "probe", {
        "probe": {"psnr_objects_db": 29.26, "psnr_by_side": {"real": 28.1, "synthetic": 30.61},
                  "cross_transfer_rel_error": 0.6835, "cross_gt_noise_rel": 0.12, "cross_by_side": side(0.54, 0.71),
                  "direct_light": {"kind": "probe", "probe": {
                      "map": [128, 64], "against_truth": {"measured_share": 0.9242, "power_ratio": 0.984,
                                                          "brightest_direction_error_deg": 0.16,
                                                          "texel_rel_error_median": 5e-5}}}},
        "point": {"psnr_objects_db": 27.01, "psnr_by_side": {"real": 27.4, "synthetic": 28.81},
                  "cross_transfer_rel_error": 0.836, "cross_gt_noise_rel": 0.12, "cross_by_side": side(0.54, 0.86),
                  "direct_light": {"kind": "point"}}})
    write(store, "interfaces_calibration", "interfaces_calibration", {
        "corner": {"interfaces": {"front": {"pose_position_rms_mm": 0.4123, "pose_position_max_mm": 0.7765,
                                            "pose_rotation_deg": 0.0912, "exposure_rel_error": -0.0021,
                                            "light_position_error_mm": 0.5432},
                                  "side": {"pose_position_rms_mm": 0.3456, "pose_rotation_deg": 0.1543,
                                           "relative_position_rms_mm": 0.6789, "relative_rotation_deg": 0.1876}}}})
    md = render_results(load_store(store))
    for text in ("30.61 dB", "28.81 dB", "0.683", "0.836", "92.4 %", "0.16 degrees", "-1.6 % off", "30 %",
                 "one point light at the probe's brightest direction"):
        assert text in md, text
    for text in ("| corner | front | 0.41 | 0.78 | 0.091 | - | - | -0.21 | 0.54 |",
                 "| corner | side | 0.35 | - | 0.154 | 0.68 | 0.188 | - | - |"):
        assert text in md, text
    for text in ("16.2 (15.2 to 17.2)", "61.5 / 3.70", "`incident_light`", "122,880 + 196,608", "9.56",
                 "76.31 dB / 64.02 dB", "0.612", "30.71 dB", "265.1", "0.00871 / 0.00872", "0.161",
                 "seed 1", "0.391", "met", "0.156", "0.143", "39.90 dB", "0.013 apart", "174 ms",
                 "machine: x86_64, vm", "wall time not recorded", "uncommitted"):
        assert text in md, text
    assert md.count(NOT_STORED) == len(RUN_BY_NAME) - 6


def test_08_live_page_tables(tmp_path):
    """The live page's runs: frames per second and latency per loop, the soak's memory and stalls, the profile's
    stages and top entries, each value as the run wrote it; a soak without its memory samples is one error."""
    store = tmp_path / "runs"
    loop = lambda fps, lat: {"frames_per_second": fps, "edit_to_pixel_ms": {"median": lat, "p95": 2 * lat},  # noqa
                             "latency_ms": {"view": {"median": lat, "p95": lat}, "light": {"median": 9 * lat,
                                                                                          "p95": 9 * lat}},
                             "capture_hz": 1.25, "longest_gap_s": 0.75, "edits_sent": 12, "edit_every_s": 0.1,
                             "last_frame_stages_ms": {"render_view": 42.5}, "last_capture_ms": {"capture": 987.6}}
    write(store, "live_fps_quick", "live_fps", {"view": [256, 192], "lf_camera": [512, 384], "rig_model": "oracle",
                                                "loops": {"decoupled": loop(4.321, 123.0), "sync": loop(1.234, 456.0)}})
    write(store, "soak_live_quick", "soak", {"minutes": 10, "loop": "decoupled", "rss_mb": [[0, 400.0], [60, 410.0],
                                                                                          [600, 411.5]],
                                             "rss_growth_after_first_minute": 0.00366, "rss_growth_limit": 0.05,
                                             "memory_flat": True, "frames": 1500, "frames_per_second": 2.5,
                                             "longest_gap_s": 0.9, "stall_limit_s": 1.0, "no_stall": True,
                                             "edit_to_pixel_ms": {"median": 300.0, "p95": 600.0},
                                             "edit_to_pixel_max_ms": 777.0, "edits_sent": 600, "edits_unseen": 0})
    write(store, "profile", "profile", {"stages_ms": {"encode": 12.34, "prefilter": 25.5}, "repeats": 20,
                                        "resolution": {"view": [1024, 768]},
                                        "py_spy": {"samples": 999, "command": "py-spy record",
                                                   "self": [["csr_matvecs (scipy)", 10.1]],
                                                   "inclusive": [["DepthPrefilter.apply (projection.py)", 17.4]]}})
    md = render_results(load_store(store))
    fps = md.split("quarter resolution: decoupled against --sync")[1].split("\n### ")[0]
    for text in ("| decoupled | sync |", "4.32", "1.23", "123 (246)", "456 (912)", "1107 (1107)", "987.6", "42.5"):
        assert text in fps, text
    soak = md.split("### A 10-minute soak")[1].split("\n### ")[0]
    for text in ("410 / 412 / 412", "0.37 %", "5.0 %", "1500, 2.50", "0.900 (1.00)", "777", "600, 0"):
        assert text in soak, text
    profile = md.split("### The pipeline profiled")[1].split("\n### ")[0]
    for text in ("`encode` | 12.3", "999 samples", "`csr_matvecs (scipy)` 10.1", "`DepthPrefilter.apply"):
        assert text in profile, text
    write(store, "soak_live_quick", "soak", {"minutes": 10})
    with pytest.raises(ResultsError, match="soak_live_quick.json: missing field 'data.rss_mb'"):
        render_results(load_store(store))


def test_09_paired_bench_table(tmp_path):
    """A paired bench (scripts/paired_bench.py): both sides named with their commits, each figure's median and
    range per side and the ratio B / A, the load at the start and the end; its summary takes the median over the
    rounds of each bench's own median."""
    import importlib.util
    from pathlib import Path

    spec = importlib.util.spec_from_file_location("paired_bench", Path(__file__).parents[2] / "scripts" /
                                                  "paired_bench.py")
    paired = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(paired)
    bench = lambda it, lf: {"pipeline_iteration_ms": it, "floor_ms": 16.0,  # noqa: E731
                            "stages_ms": {"render_lightfield": {"median": lf}}}
    rows = paired.summarise([bench(90.0, 30.0), bench(80.0, 25.0), bench(85.0, 40.0)],
                            [bench(60.0, 18.0), bench(70.0, 19.0), bench(65.0, 17.0)])
    by = {r["figure"]: r for r in rows}
    assert [r["figure"] for r in rows][:2] == ["pipeline_iteration_ms", "render_lightfield"]
    assert by["pipeline_iteration_ms"]["a_ms"] == 85.0 and by["pipeline_iteration_ms"]["b_range"] == [60.0, 70.0]
    assert by["render_lightfield"]["ratio"] == pytest.approx(18.0 / 30.0)
    assert by["floor_ms"]["ratio"] == 1.0
    store = tmp_path / "runs"
    write(store, "paired_84066a4", "paired", {
        "a": {"ref": "84066a4", "commit": "84066a4" + "0" * 33, "label": "84066a4 (84066a4a)"},
        "b": {"ref": "HEAD", "commit": "1" * 40, "label": "HEAD (11111111)"},
        "bench_args": ["--rig-model", "oracle"], "rounds": 3,
        "machine": {"load_average_start": [1.5, 1.25, 1.0], "load_average_end": [2.0, 1.75, 1.5]}, "rows": rows})
    md = render_results(load_store(store))
    section = md.split("### The pipeline against commit 84066a4")[1].split("\n### ")[0]
    for text in ("A = 84066a4 (84066a4a), B = HEAD (11111111)", "`lft bench --rig-model oracle`", "3 benches each",
                 "1.50 / 1.25 / 1.00 at the start", "`pipeline_iteration_ms` | 85.0 (80.0 to 90.0) | 65.0 (60.0 to "
                 "70.0) | 0.765", "`render_lightfield` | 30.0 (25.0 to 40.0) | 18.0 (17.0 to 19.0) | 0.600"):
        assert text in section, text
    write(store, "paired_84066a4", "paired", {"a": {}, "b": {}})
    with pytest.raises(ResultsError, match="paired_84066a4.json: missing field 'data.rows'"):
        render_results(load_store(store))


def test_the_pitch_study_answers_the_pitch_for_a_target_error():
    """A power law error = 0.004 pitch^1.0 gives pitch 12.5 mm for an error of 0.05 (within the measured pitches);
    a flat curve gives no answer; the table carries the floors and the answer for each scene."""
    from lftransfer.reports.results_study import pitch_for, study_tables

    pitches = {"a": 10.0, "b": 20.0, "c": 40.0}
    fit = pitch_for(pitches, {s: 0.004 * p for s, p in pitches.items()})
    assert fit["pitch_mm"] == pytest.approx(12.5) and fit["exponent"] == pytest.approx(1.0)
    assert not fit["extrapolated"]
    assert pitch_for(pitches, {"a": 0.1, "b": 0.1, "c": 0.1}) is None
    assert pitch_for(pitches, {s: 0.02 * p for s, p in pitches.items()})["extrapolated"]      # 2.5 mm: below 10
    summary = {m: [{"scene": "fig4", "setting": s, "mean": v * p} for s, p in pitches.items()]
               for m, v in (("cross_transfer_rel_error", 0.005), ("floor_transfer", 0.004), ("floor", 0.002))}
    text = "\n".join(study_tables({"scenes": ["fig4"], "settings": list(pitches), "pitches": pitches,
                                   "summary": summary}))
    assert "| fig4 | a | 10 |" in text.replace("10.0", "10") and "12.5" in text and "25" in text

"""``lft render``: sequences over an animation, their files, per-frame metrics and --resume."""

from __future__ import annotations

import json

import numpy as np
import pytest

from lftransfer.runs.pipeline import RunOptions

from lftransfer.scenes import quick_scene
from lftransfer.runs.sequence import SequenceError, SequenceOptions, read_depth, render_sequence, sequence_times
from lftransfer.imageio_utils import read_exr
from lftransfer.scenes import builtin_scene, load_scene, with_overrides


def _moving_scene():
    """fig4 at an eighth of the paper's resolution, the synthetic cube sliding 2 cm over 3 frames."""
    scene = quick_scene(load_scene(builtin_scene("fig4")))
    cube = scene.synthetic[0].model_dump()
    x, y, z = cube["translate"]
    cube["keyframes"] = [{"time_s": 0.0}, {"time_s": 0.5, "translate": [x, y + 0.02, z]}]
    return with_overrides(scene, view={"resolution": [128, 96]}, render={"gt_spp": 16},
                          rig={"lf_camera": [256, 192], "projector": [256, 192], "angular_samples": 8},
                          animation={"duration_s": 0.5, "fps": 6}, synthetic=[cube])


def test_01_frame_times():
    scene = _moving_scene()
    assert sequence_times(scene, SequenceOptions()).tolist() == pytest.approx([0, 1 / 6, 2 / 6])
    assert len(sequence_times(scene, SequenceOptions(frames=5))) == 5          # holds the last pose after the end
    still = load_scene(builtin_scene("fig4"))
    assert sequence_times(still, SequenceOptions()).tolist() == [0.0] * 8
    assert sequence_times(still, SequenceOptions(mode="converged")).tolist() == [0.0]
    with pytest.raises(SequenceError, match="mode must be one of live, converged"):
        SequenceOptions(mode="fast")


def test_02_live_sequence_files_metrics_and_resume(variant, tmp_path):
    """Every frame is written (EXR, PNG, panel), the videos and the report; verified frames carry metrics that
    see the moving cube; an interrupted sequence resumes after its last finished frame without touching it."""
    scene = _moving_scene()
    out = tmp_path / "seq"
    options = RunOptions(rig_model="oracle", truth_seed=None)
    seen = []

    def stop_after_two(record, done, total):
        seen.append(record.index)
        if done == 2:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        render_sequence(scene, out, options, SequenceOptions(verify_every=2), progress=stop_after_two)
    assert json.loads((out / "status.json").read_text())["state"] == "interrupted"
    first = (out / "frames" / "0000.exr").read_bytes()
    with pytest.raises(SequenceError, match="other settings"):
        render_sequence(scene, out, options, SequenceOptions(verify_every=2, mode="converged", resume=True))
    report = render_sequence(scene, out, options, SequenceOptions(verify_every=2, resume=True),
                             progress=lambda r, d, n: seen.append(r.index))
    assert seen == [0, 1, 2]
    assert [f["index"] for f in report["frames"]] == [0, 1, 2]
    assert (out / "frames" / "0000.exr").read_bytes() == first
    for name in ("composite.mp4", "bounces.mp4", "report.json", "state/projected_lf.npz", "frames/0002.png",
                 "frames/panel_0002.png"):
        assert (out / name).is_file(), name
    assert json.loads((out / "status.json").read_text())["state"] == "complete"
    # the depth the prefilter measured before frame 0 is kept; the resumed loop prefilters with it, unmeasured
    depth = read_depth(out)
    assert depth is not None and depth.shape[1:] == (8, 8) and np.isfinite(depth).mean() > 0.05
    timings = [f["timings_s"] for f in report["frames"]]
    assert "measure_depth" in timings[0] and not any("measure_depth" in t for t in timings[1:])
    verified = [f for f in report["frames"] if f["metrics"]]
    assert [f["index"] for f in verified] == [0, 2]
    assert all(f["metrics"]["psnr_objects_db"] > 20 for f in verified)
    a, b = (read_exr(out / "frames" / f"{i:04d}.exr") for i in (0, 2))
    assert np.abs(a - b).mean() > 1e-3 * np.abs(a).mean()                       # the cube moved
    # the exchange check: frame 2 (after the 2 warm-up frames) gets its cross error, frame 0 the reason it has none
    from lftransfer.runs.effects import verify_exchange

    verify_exchange(scene, out, options, report)
    checked = json.loads((out / "report.json").read_text())
    frame0, frame2 = checked["frames"][0]["metrics"], checked["frames"][2]["metrics"]
    assert frame2["cross_transfer_rel_error"] is not None and "cross_transfer_rel_error" not in frame0
    assert "a warm-up frame" in frame0["undefined"]["cross_transfer_rel_error"]
    for name in ("error_0002.png", "cross_term_0002.png"):                  # its pictures, as a run's
        assert (out / "frames" / name).stat().st_size > 0, name


def test_03_frame_metrics_see_a_dark_real_object(variant):
    """psnr_real_db, with the real objects' own peak, drops when the real object is black in the composite,
    where the full-frame figure hardly moves (its peak is the brightest thing in view)."""
    from lftransfer.runs.sequence import frame_metrics
    from lftransfer.sim.ground_truth import GroundTruth

    rng = np.random.default_rng(0)
    h, w = 96, 128
    real = np.zeros((h, w), np.float32)
    real[20:60, 10:50] = 1
    syn = np.zeros((h, w), np.float32)
    syn[30:50, 80:100] = 1
    image = (0.05 * real[..., None] + 30.0 * syn[..., None] * np.ones(3)).astype(np.float32)
    union = np.stack([image + 1e-4 * rng.standard_normal(image.shape).astype(np.float32) for _ in range(2)])
    gt = GroundTruth(union=union, real=union, synthetic=union, alpha_real=real, alpha_synthetic=syn)
    good = frame_metrics(image, gt)
    dark = frame_metrics(image * (1 - real[..., None]), gt)
    assert good["psnr_real_db"] > 40 and dark["psnr_real_db"] < 10
    assert good["psnr_db"] - dark["psnr_db"] < good["psnr_real_db"] - dark["psnr_real_db"]


def test_03b_frame_metrics_score_the_hidden_pixels():
    """Where the ground truth has a real object in front of a synthetic one, a frame's metrics score those pixels,
    for the frame and for the same frame by the over operator; a frame with nothing hidden has neither."""
    from lftransfer.runs.sequence import frame_metrics
    from lftransfer.sim.ground_truth import GroundTruth

    h, w = 48, 64
    syn = np.zeros((h, w), np.float32)
    syn[10:30, 10:40] = 1
    real = np.zeros((h, w), np.float32)
    real[:, 20:26] = 1
    d_syn = np.where(syn > 0, 1.0, np.inf).astype(np.float32)
    d_real = np.where(real > 0, 0.5, np.inf).astype(np.float32)
    image = np.where(real[..., None] > 0, 0.3, syn[..., None] * np.array([0.1, 0.6, 0.1])).astype(np.float32)
    union = np.stack([image, image + np.float32(1e-4)])
    gt = GroundTruth(union=union, real=union, synthetic=union, alpha_real=real, alpha_synthetic=syn,
                     depth_real=d_real, depth_synthetic=d_syn)
    over = np.where(syn[..., None] > 0, syn[..., None] * np.array([0.1, 0.6, 0.1]), image).astype(np.float32)
    m = frame_metrics(image + np.float32(1e-3), gt, over)
    assert m["psnr_hidden_db"] > 40 and m["psnr_hidden_over_db"] < 20
    flat = GroundTruth(union=union, real=union, synthetic=union, alpha_real=real, alpha_synthetic=syn)
    assert "psnr_hidden_db" not in frame_metrics(image, flat, over)


def test_03c_a_verified_frame_keeps_its_depth(tmp_path):
    """A verified frame's depth (the LF camera's and in the view camera) reads back as it was written, for its
    check to composite the frame without exchange alike; a frame that kept none reads as None."""
    from lftransfer.runs.sequence import read_frame_depth, write_frame_depth
    from lftransfer.real_depth import ViewDepth

    rng = np.random.default_rng(1)
    depth = rng.random((4, 3, 3)).astype(np.float32)
    vd = ViewDepth(rng.random((6, 8)).astype(np.float32), rng.random((6, 8)).astype(np.float32), "lightfield")
    write_frame_depth(tmp_path, 12, depth, vd)
    back, view = read_frame_depth(tmp_path, 12)
    assert np.array_equal(back, depth) and np.array_equal(view.depth, vd.depth)
    assert np.array_equal(view.sigma, vd.sigma) and view.source == "lightfield"
    assert read_frame_depth(tmp_path, 13) is None


def test_04_converged_resume_fills_gaps(variant, tmp_path):
    """Converged frames are independent: a resumed sequence renders exactly the frames that are missing (a cluster
    finishes them in any order), and they come out bit-identical to the first run's."""
    scene = _moving_scene()
    out = tmp_path / "seq"
    options = RunOptions(rig_model="oracle", truth_seed=3)
    seq = SequenceOptions(mode="converged", frames=3)
    render_sequence(scene, out, options, seq)
    before = read_exr(out / "frames" / "0001.exr")
    (out / "frames" / "0001.exr").unlink()
    seen = []
    report = render_sequence(scene, out, options, SequenceOptions(mode="converged", frames=3, resume=True),
                             progress=lambda r, d, n: seen.append((r.index, d, n)))
    assert seen == [(1, 3, 3)]
    assert [f["index"] for f in report["frames"]] == [0, 1, 2]
    assert np.array_equal(read_exr(out / "frames" / "0001.exr"), before)


def test_05_the_synthetic_lights_stand_where_the_model_says(variant, tmp_path):
    """A sequence knows the rig as ``lft run`` does (``pipeline.knowledge``): with the oracle its synthetic point
    lights stand where the simulated world's really are (each a few millimetres from the scene file's position),
    with a calibration file where that file measured them; the nominal model keeps the file's positions."""
    from lftransfer.runs.pipeline import open_rig
    from lftransfer.runs.sequence import acquire_model
    from lftransfer.calibration.light import LightFit
    from tests.small import nominal_calibration

    scene = quick_scene(load_scene(builtin_scene("fig4")))
    scene = with_overrides(scene, lights=[*scene.lights, {"position": [0.22, -0.10, 0.0]}])
    opened = open_rig(scene, RunOptions(truth_seed=3))
    try:
        oracle = acquire_model(opened, scene, RunOptions(truth_seed=3, rig_model="oracle"), tmp_path, False, print)
        assert [lt.position for lt in oracle.scene.lights] == [lt.position for lt in opened.oracle.world.lights]
        assert oracle.scene.lights != scene.lights and oracle.model is opened.oracle.model
        nominal = acquire_model(opened, scene, RunOptions(truth_seed=3, rig_model="nominal"), tmp_path, False, print)
        assert nominal.scene.lights == scene.lights
        cal = nominal_calibration(scene.synthetic_part())
        cal.lights = [LightFit(position=p, start=lt.position, intensity_albedo=(1, 1, 1), dark_ratio=0.25,
                               residual_rms=0.001, std_mm=(0, 0, 0), pixels=1, boards=4)
                      for p, lt in zip([(0.301, 0.121, 0.0), (0.219, -0.099, 0.001)], scene.lights)]
        path = cal.write(tmp_path / "cal.json")
        known = acquire_model(opened, scene, RunOptions(truth_seed=3, calibration=path), tmp_path, False, print)
        assert [tuple(lt.position) for lt in known.scene.lights] == [(0.301, 0.121, 0.0), (0.219, -0.099, 0.001)]
        assert known.rig_model == f"calibration file {path}"
    finally:
        opened.rig.close()


def test_06_a_live_sequence_with_moving_real_objects_projects_the_box_light_field():
    """The live loop measures the real scene's depth once, so a scene whose real objects move is projected the box
    light field, and its report says so; a converged sequence measures the depth in every frame."""
    from lftransfer.runs.sequence import _projection
    from lftransfer.settings import Overrides, resolve_settings
    from lftransfer.transfer.bounce import TransferSettings

    still = _moving_scene()
    block = still.real[0].model_dump()
    x, y, z = block["translate"]
    block["keyframes"] = [{"time_s": 0.0}, {"time_s": 0.5, "translate": [x, y + 0.01, z]}]
    moving = with_overrides(still, real=[block])
    assert resolve_settings(still).transfer.projection == "solve"          # the scenes' default
    kept = resolve_settings(still, live=True)
    note = _projection(SequenceOptions(), kept)
    assert kept.transfer.projection == "solve" and kept.adjustments == () and "measured once" in note[0]
    box = resolve_settings(moving, live=True)
    note = _projection(SequenceOptions(), box)
    assert box.transfer.projection == "box" and "the real objects move" in note[0]
    assert note == list(box.adjustments)
    converged = resolve_settings(moving)                                    # a converged sequence: not live
    note = _projection(SequenceOptions(mode="converged"), converged)
    assert converged.transfer.projection == "solve" and "in every frame" in note[0]
    plain = resolve_settings(moving, Overrides(projection="box"), live=True)
    assert plain.transfer.projection == "box" and _projection(SequenceOptions(), plain) == []
    # the non-area rule holds however the settings are built
    point = TransferSettings(lighting_model="point", reconstruction="linear", projection="solve", window="edge")
    assert (point.reconstruction, point.projection, point.window) == ("box", "box", "cut")


def test_08_decoupled_live_sequence(variant, tmp_path):
    """``--loop decoupled``: every frame is rendered with the newest capture, and its record says which capture
    that was, how far behind in scene time and how old; the frames see the moving cube as the synchronous ones
    do (the synthetic side never waits for a capture). A converged sequence refuses the option."""
    scene = _moving_scene()
    options = RunOptions(rig_model="oracle", truth_seed=None)
    report = render_sequence(scene, tmp_path / "dec", options, SequenceOptions(loop="decoupled", frames=6,
                                                                               verify_every=2))
    assert report["loop"] == "decoupled"
    captures = [f["capture"] for f in report["frames"]]
    assert all(c["behind_s"] >= 0 and c["age_s"] > 0 for c in captures)
    assert np.all(np.diff([c["index"] for c in captures]) >= 0)
    assert all(f["metrics"]["psnr_objects_db"] > 20 for f in report["frames"] if f["metrics"])
    assert report["summary"]["captures_used"] >= 1 and "capture_behind_s_median" in report["summary"]
    sync = render_sequence(scene, tmp_path / "sync", options, SequenceOptions(frames=2))
    assert sync["loop"] == "sync" and all(f["capture"]["behind_s"] == 0 for f in sync["frames"])
    with pytest.raises(SequenceError, match="--loop decoupled needs --mode live"):
        SequenceOptions(mode="converged", loop="decoupled")
    with pytest.raises(ValueError, match="loop"):
        SequenceOptions(loop="fast")

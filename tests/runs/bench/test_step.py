"""``lft bench``'s library side: it times ``LiveTransfer.step`` itself, with the demo's settings and the rig model
a run uses, beside the ray-casting floor. Plumbing only: no assertion on how fast anything is."""

from __future__ import annotations

import json
from dataclasses import replace

import pytest

from lftransfer.runs import pipeline, rigs
from lftransfer.settings import Overrides
from lftransfer.runs.bench.step import (PIPELINE_STAGES, RIG_STAGES, BenchOptions, count_bench_steps, run_bench,
                                       transfer_settings)
from lftransfer.imageio_utils import strict_json
from lftransfer.scenes import builtin_scene, load_scene, quick_scene
from lftransfer.transfer.bounce import TransferSettings
from lftransfer.transfer.live import LiveTransfer
from tests.small import nominal_calibration, write_tiny_scene


def _counting_step(monkeypatch) -> list:
    """Count the calls of the live loop's own step function (still running it)."""
    calls = []
    step = LiveTransfer.step

    def counted(self, time_s):
        calls.append(time_s)
        return step(self, time_s)

    monkeypatch.setattr(LiveTransfer, "step", counted)
    return calls


@pytest.fixture(scope="module")
def quick_fig4():
    return quick_scene(load_scene(builtin_scene("fig4")))


@pytest.fixture(scope="module")
def oracle_bench(quick_fig4):
    """The bench at quarter resolution on the Fig. 4 scene, with the oracle model (plumbing), two timed frames."""
    options = BenchOptions(iterations=2, rig_model="oracle", peer=False, exact_aperture_samples=8)
    messages = []
    with pytest.MonkeyPatch.context() as mp:
        calls = _counting_step(mp)
        result = run_bench(quick_fig4, options, progress=messages.append)
    return options, result, calls, messages


def test_01_times_the_live_step_itself(oracle_bench):
    options, result, calls, messages = oracle_bench
    assert len(calls) == options.warmup + options.iterations
    assert len(messages) == count_bench_steps(quick_scene(load_scene(builtin_scene("fig4"))), options)
    # the scene's default projection, the solve: its target's rays instead of the prefilter, no light probe
    assert tuple(result.stages_ms) == tuple(k for k in PIPELINE_STAGES if k not in ("prefilter", "steep_room"))
    assert tuple(result.rig_stages_ms) == RIG_STAGES
    assert result.pipeline_iteration_ms >= result.floor_ms > 0
    assert result.iteration_over_floor == pytest.approx(result.pipeline_iteration_ms / result.floor_ms, rel=1e-2)
    assert result.capture_ms > 0 and result.step_total_ms >= result.pipeline_iteration_ms
    # the pipeline's share is the sum of its stages (median over frames), never the captures
    assert result.pipeline_iteration.min <= result.pipeline_iteration_ms <= result.pipeline_iteration.max


def test_02_the_floor_casts_the_steps_own_rays(oracle_bench, quick_fig4):
    _, result, _, _ = oracle_bench
    s = transfer_settings(quick_fig4)
    from lftransfer.lightfield import LightField

    opened = rigs.open_rig(quick_fig4, pipeline.RunOptions(truth_seed=0))
    array = opened.oracle.model.array                                      # the oracle model's, as the bench used
    opened.rig.close()
    entries = array.K * int(LightField.zeros(array, s.angular_samples, s.angular_samples).mask().sum())
    w, h = quick_fig4.view.resolution
    assert s.projection == "solve"
    # light field: entries with data; the solve's target: its rays; the view
    assert result.floor.rays == (entries * s.lf_spp, result.surface_solve["rays"], w * h * s.view_spp)
    assert result.surface_solve["rays"] > 0
    assert result.floor.geometry in ("scene", "renderer")
    assert result.floor_ms == min(result.floor.scene_geometry_ms, result.floor.renderer_geometry_ms)


def test_03_the_json_has_the_settings(oracle_bench, quick_fig4):
    _, result, _, _ = oracle_bench
    data = json.loads(json.dumps(strict_json(result.to_json()), allow_nan=False))
    s = data["settings"]
    render = quick_fig4.render
    assert s["lf_spp"] == s["view_spp"] == render.spp
    assert s["angular_samples"] == quick_fig4.rig.angular_samples
    assert s["aperture_samples"] == render.aperture_samples
    assert s["lighting_model"] == render.lighting_model and s["reconstruction"] == render.reconstruction
    assert s["renderer"] == {"asked": "auto", "used": "fast"}
    assert s["resolution"]["view"] == list(quick_fig4.view.resolution)
    assert s["resolution"]["lf_camera"] == list(quick_fig4.rig.lf_camera)
    assert "oracle" in s["rig_model"] and "not what users run" in s["rig_model"]
    assert s["truth_seed"] == 0 and s["variant"] and s["scene"].endswith("fig4.toml")
    assert data["pipeline_iteration_ms"] >= data["floor_ms"] > 0
    assert data["fast_vs_exact"]["psnr_db"] > 40 and data["peer"] is None
    assert any("fast path approximates" in n for n in data["notes"])


def test_04_settings_are_the_demos(tmp_path, monkeypatch):
    """The bench's settings are those the demo's run hands the transfer (bounce-loop fields aside)."""
    scene = load_scene(write_tiny_scene(tmp_path / "tiny.toml"))

    class Seen(Exception):
        pass

    def stop(rig, model, pipeline_scene, settings, **kw):
        raise Seen(settings)

    monkeypatch.setattr(pipeline, "run_transfer", stop)
    with pytest.raises(Seen) as seen:
        pipeline.run_scene(scene, tmp_path / "run", pipeline.RunOptions(rig_model="nominal"))
    demo: TransferSettings = seen.value.args[0]
    ours = transfer_settings(scene)
    assert ours == replace(demo, bounces=ours.bounces, bounce_views=ours.bounce_views,
                           projector_fill=ours.projector_fill)


@pytest.fixture
def tiny(tmp_path):
    return load_scene(write_tiny_scene(tmp_path / "tiny.toml"))


def test_05_calibrates_first_without_a_file(tiny, monkeypatch):
    done = []

    def calibrate(rig, scene, *, progress=None, rigs=()):
        done.append(scene)
        return nominal_calibration(tiny)

    monkeypatch.setattr(rigs, "calibrate", calibrate)
    calls = _counting_step(monkeypatch)
    result = run_bench(tiny, BenchOptions(iterations=1, peer=False, accuracy=False))
    assert len(done) == 1 and not hasattr(done[0], "real")                      # the synthetic part only
    assert len(calls) == 3                                                     # 2 warm-up + 1 timed
    assert result.settings["rig_model"].startswith("calibrated (by the bench")
    assert result.settings["calibration_file"] is None and result.fast_vs_exact is None


def test_06_uses_a_calibration_file(tiny, tmp_path, monkeypatch):
    path = nominal_calibration(tiny).write(tmp_path / "calibration.json")
    monkeypatch.setattr(rigs, "calibrate", lambda *a, **k: pytest.fail("calibrated despite the file"))
    result = run_bench(tiny, BenchOptions(iterations=1, calibration=path, peer=False, accuracy=False))
    assert result.settings["rig_model"] == f"calibrated (calibration file {path})"
    assert result.settings["calibration_file"] == str(path)
    assert result.pipeline_iteration_ms >= result.floor_ms > 0


def test_07_peer_and_options(tiny):
    result = run_bench(tiny, BenchOptions(iterations=1, rig_model="nominal", accuracy=False, peer_max_spp=4,
                                          settings=Overrides(lighting_model="point", renderer="exact")))
    assert result.settings["lighting_model"] == "point" and result.settings["reconstruction"] == "box"
    assert result.settings["renderer"]["used"] == "exact" and result.cache_vertices is None
    p = result.peer
    assert p.ours_ms > 0 and p.peer_ms > 0 and p.peer_spp <= 4 and p.ours_spp == tiny.render.spp
    assert p.reached_target == (p.peer_rmse <= p.ours_rmse)


@pytest.mark.parametrize("kw", [{"iterations": 0}, {"warmup": 0}, {"rig_model": "guessed"}])
def test_08_rejects_bad_options(kw):
    with pytest.raises(ValueError):
        BenchOptions(**kw)


def test_live_moves_a_synthetic_object_every_frame(quick_fig4):
    """--live: the still Fig. 4 scene's cube moves in every timed frame (and stays in its half-space), the step's
    frame rates are reported, and the fast path is measured against the exact path over the cube's pixels."""
    from lftransfer.runs.bench.step import LIVE_SLIDE_M, with_moving_object

    moving = with_moving_object(quick_fig4, 4)
    assert moving.moving and not quick_fig4.moving
    cube0, cube_mid = moving.at(0.0).synthetic[0], moving.at(moving.animation.duration_s / 2).synthetic[0]
    assert cube_mid.translate[1] - cube0.translate[1] == pytest.approx(LIVE_SLIDE_M)
    assert with_moving_object(moving, 4) is moving                           # its own motion is kept
    options = BenchOptions(iterations=3, rig_model="oracle", peer=False, exact_aperture_samples=8, decoupled=True)
    result = run_bench(moving, options)
    assert result.frames_moved == 3
    # latency: every timed frame moved the cube; synchronously its view shows in the same step and its light one
    # step later; decoupled, the view in the next frame and the light after a capture
    sync = result.latency_ms["sync"]
    assert sync["view"]["count"] >= 2 and sync["view"]["median"] < sync["light"]["median"]
    step_ms = result.step_total_ms
    assert sync["view"]["median"] == pytest.approx(step_ms, rel=0.5)
    d = result.decoupled
    assert d.frames >= 10 and d.captures >= 3 and d.render_fps > 0 and d.capture_hz > 0
    dec = result.latency_ms["decoupled"]
    assert dec["view"]["median"] < dec["light"]["median"]
    assert "capture" not in d.stages_ms and set(d.capture_stages_ms) == {"encode", "capture", "decode",
                                                                        "capture_view"}
    assert json.loads(json.dumps(result.to_json(), default=strict_json))["decoupled"]["frames"] == d.frames
    assert result.pipeline_fps == pytest.approx(1000 / result.pipeline_iteration_ms, rel=1e-2)
    assert 0 < result.step_fps <= result.pipeline_fps
    f = result.fast_vs_exact
    assert f.psnr_objects_db is not None and f.psnr_db is not None
    assert f.psnr_objects_db < f.psnr_db             # the errors sit on the cube: the whole frame dilutes them
    with pytest.raises(ValueError, match="no synthetic object"):
        from lftransfer.scenes import with_overrides

        with_moving_object(with_overrides(quick_fig4, synthetic=[]), 4)

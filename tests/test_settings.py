"""Settings are resolved once (lftransfer.settings): every default and override path gives the settings a run
reports and uses, and a run's progress total is the number of steps it takes."""

from __future__ import annotations

import dataclasses
import json

import pytest
from typer.testing import CliRunner

from lftransfer import choices
from lftransfer.runs.pipeline import RunOptions, count_run_steps, run_scene
from lftransfer.scenes import builtin_scene, builtin_scenes, load_scene, with_overrides
from lftransfer.scenes.models import RenderConfig
from lftransfer.settings import COMPARABLE, Overrides, RunSettings, resolve_settings
from lftransfer.transfer.bounce import TransferSettings
from tests.small import nominal_calibration, write_tiny_scene


def test_each_default_is_defined_once():
    """The scene model, the transfer's settings and the choices module agree on every default."""
    render, transfer = RenderConfig(), TransferSettings()
    for name in ("lighting_model", "reconstruction", "projection", "window"):
        default = getattr(choices, f"DEFAULT_{name.upper()}")
        assert getattr(render, name) == getattr(transfer, name) == default, name
    assert render.spp == transfer.view_spp == transfer.lf_spp == choices.DEFAULT_SPP
    assert render.gt_spp == choices.DEFAULT_GT_SPP and render.aperture_samples == transfer.aperture_samples
    assert transfer.bounces == choices.DEFAULT_BOUNCES and transfer.renderer == choices.DEFAULT_RENDERER
    assert RunOptions().rig_model == choices.DEFAULT_RIG_MODEL
    from lftransfer.runs.study import StudyConfig

    study = StudyConfig(scenes=["fig4"], setting=[{"name": "a"}])
    assert study.rig_model == choices.DEFAULT_RIG_MODEL and study.bounces == choices.DEFAULT_BOUNCES
    assert set(choices.LIGHTING_MODELS) == set(RenderConfig.model_fields["lighting_model"].annotation.__args__)


@pytest.mark.parametrize("name", builtin_scenes())
def test_a_scene_without_overrides_runs_as_its_file_says(name):
    scene = load_scene(builtin_scene(name))
    s = resolve_settings(scene)
    r = scene.render
    assert (s.transfer.lighting_model, s.transfer.reconstruction, s.transfer.projection, s.transfer.window) == \
        (r.lighting_model, r.reconstruction, r.projection, r.window)
    assert s.transfer.angular_samples == scene.rig.angular_samples and s.gt_spp == r.gt_spp
    assert s.transfer.lf_spp == (r.lf_spp or r.spp) and s.transfer.view_spp == r.spp
    assert s.comparisons == ()


def test_overrides_win_and_only_the_area_model_has_reconstruction_projection_window():
    scene = load_scene(builtin_scene("fig4"))
    s = resolve_settings(scene, Overrides(bounces=5, reconstruction="box", gt_spp=7, renderer="exact"))
    assert (s.bounces, s.transfer.reconstruction, s.gt_spp, s.transfer.renderer) == (5, "box", 7, "exact")
    assert s.transfer.projection == scene.render.projection                  # not overridden: the scene's
    point = resolve_settings(scene, Overrides(lighting_model="point", window="edge")).transfer
    assert (point.reconstruction, point.projection, point.window) == ("box", "box", "cut")
    assert not point.prefilters
    # the comparisons: none equal to the run's own value; area-only choices dropped under another model
    every = resolve_settings(scene, Overrides.comparing_all())
    assert every.comparisons == (("lighting_model", "point"), ("reconstruction", "box"), ("projection", "box"),
                                 ("projection", "depth"), ("window", "cut"))
    assert resolve_settings(scene, Overrides.comparing_all(lighting_model="point")).comparisons == \
        (("lighting_model", "area"),)
    rerun = every.rerun("lighting_model", "point")
    assert (rerun.lighting_model, rerun.window, rerun.bounce_views) == ("point", "cut", False)
    assert every.rerun("window", "cut") == dataclasses.replace(every.transfer, window="cut", bounce_views=False)
    # a comparison is the run that asks for that value: the area model back brings the scene's own choices
    point_first = resolve_settings(scene, Overrides.comparing_all(lighting_model="point"))
    assert point_first.rerun("lighting_model", "area") == dataclasses.replace(
        resolve_settings(scene).transfer, bounce_views=False)


@pytest.mark.parametrize("bad", [dict(bounces=choices.MAX_BOUNCES + 1), dict(bounces=-1), dict(gt_spp=0),
                                 dict(window="soft"), dict(renderer="fastest"),
                                 dict(compare=(("window", ("soft",)),)), dict(compare=(("bounces", (1,)),))])
def test_bad_overrides_are_refused_with_their_name(bad):
    with pytest.raises(ValueError, match=next(iter(bad)) if "compare" not in bad else "compare"):
        Overrides(**bad)


@pytest.fixture
def tiny(tmp_path):
    return load_scene(write_tiny_scene(tmp_path / "tiny.toml", view=(32, 24), gt_spp=4))


def _run_counting(scene, out, options, monkeypatch):
    """Run with a progress callback; also keep the settings each transfer of the run received."""
    import lftransfer.runs.pipeline as pipeline

    seen, given = [], []
    real = pipeline.run_transfer

    def transfer(rig, model, scene_, settings, **kw):
        given.append(settings)
        return real(rig, model, scene_, settings, **kw)

    monkeypatch.setattr(pipeline, "run_transfer", transfer)
    report = run_scene(scene, out, options, progress=lambda msg, done: seen.append(done))
    return report, seen, given


@pytest.mark.parametrize("case", ["compare_and_control", "calibration_file", "unverified_point", "quiet_no_floor"])
def test_the_progress_total_is_the_steps_a_run_takes_and_the_report_says_what_it_used(variant, tiny, tmp_path,
                                                                                      case, monkeypatch):
    """The progress total (count_run_steps) equals the steps the run makes, on runs that take every branch:
    comparison re-runs (area and point models), the negative control, a calibration file, no verification; and
    report.json's settings are the resolved ones, which the transfer received."""
    if case == "compare_and_control":
        options = RunOptions(settings=Overrides.comparing_all(bounces=1), rig_model="oracle", truth_seed=3,
                             negative_control=True, use_cache=False, capture_spp=1)
    elif case == "calibration_file":
        path = nominal_calibration(tiny).write(tmp_path / "given" / "calibration.json")
        options = RunOptions(settings=Overrides(bounces=1), calibration=path, truth_seed=3, use_cache=False,
                             capture_spp=1)
    elif case == "unverified_point":
        options = RunOptions(settings=Overrides(bounces=2, lighting_model="point"), rig_model="nominal",
                             verify=False, capture_spp=1)
    else:               # a quiet reference (rounds of unknown number), no fidelity floor
        options = RunOptions(settings=Overrides(bounces=1, gt_spp=16, quiet_reference=True, reference_budget_s=600),
                             rig_model="oracle",
                             truth_seed=3, use_cache=False, capture_spp=1, floor=False)
    report, seen, given = _run_counting(tiny, tmp_path / "out", options, monkeypatch)
    assert seen == list(range(1, len(seen) + 1))
    assert seen[-1] == count_run_steps(tiny, options)
    resolved = resolve_settings(tiny, options.settings)
    assert report["settings"] == json.loads(json.dumps(resolved.to_json()))
    # what the transfers received: the run's settings, then each comparison's, the solve's two ablations (the
    # oracle's depth, the moved depth) and the control's, these without their bounce views
    plain = dataclasses.replace(resolved.transfer, bounce_views=False)
    ablations = [plain, plain] if report["surface_ablations"] else []
    control = [plain] if report["negative_control"] else []
    assert given == [resolved.transfer, *resolved.reruns, *ablations, *control]
    assert (report["surface_ablations"] is not None) == (case == "compare_and_control")
    assert report["lighting_model"] == resolved.transfer.lighting_model
    if case == "compare_and_control":
        assert set(report["by_lighting_model"]) == {"area", "point"} and report["negative_control"] is not None
        assert report["synthetic_lights"].startswith("the oracle")
    if case == "calibration_file":        # a file without its light section: said, not silently the scene's light
        assert report["synthetic_lights"] == "the scene file"
        assert [w for w in report["warnings"] if "no light section" in w and str(path) in w]
    else:
        assert not [w for w in report["warnings"] if "no light section" in w]
    if case == "quiet_no_floor":
        assert report["reference"]["met"] and report["reference"]["first_spp"] == 16
        assert report["fidelity_floor"] is None and "--no-floor" in report["undefined_metrics"]["fidelity_floor"]
    elif case == "compare_and_control":     # the simulated rig, verified: the floor is found, the reference fixed
        assert report["fidelity_floor"]["floor"] is not None and report["reference"] is None


def test_the_command_line_reports_the_settings_it_resolved(variant, tiny, tmp_path):
    """``lft run --lighting-model point --bounces 1``: report.json's settings are resolve_settings' of the same
    overrides (the command line adds its defaults: the renderer, and a quiet reference)."""
    from lftransfer.app.cli import app

    out = tmp_path / "cli"
    result = CliRunner().invoke(app, ["run", str(tiny.source), "--lighting-model", "point", "--bounces", "1",
                                      "--rig-model", "nominal", "--exact-rig", "--out", str(out), "--no-cache"])
    assert result.exit_code == 0, (result.output, result.exception)
    report = json.loads((out / "report.json").read_text())
    expected = resolve_settings(tiny, Overrides(lighting_model="point", bounces=1, renderer=choices.DEFAULT_RENDERER,
                                                quiet_reference=True))          # lft run judges its run
    assert report["settings"] == json.loads(json.dumps(expected.to_json()))
    assert report["settings"]["transfer"]["window"] == "cut"


def test_run_settings_serialise_every_field():
    s = resolve_settings(with_overrides(load_scene(builtin_scene("fig4")), render={"spp": 8}))
    data = s.to_json()
    assert set(data["transfer"]) == {f.name for f in dataclasses.fields(TransferSettings)}
    assert data["transfer"]["view_spp"] == 8 and isinstance(s, RunSettings)
    assert set(COMPARABLE) <= set(data["transfer"])


@pytest.mark.parametrize("name", builtin_scenes())
def test_resolved_settings_hold_final_values(name):
    """What resolve_settings returns names the renderer the scene gets ("fast" or "exact", never "auto") and the
    scene's max_depth; resolving an already resolved renderer gives it again; a light probe scene takes the exact
    path, and asking it for the fast path is refused with the setting's name."""
    from lftransfer.render.selection import resolve_renderer

    scene = load_scene(builtin_scene(name))
    s = resolve_settings(scene).transfer
    assert s.renderer in ("fast", "exact") and s.max_depth == scene.render.max_depth
    assert resolve_renderer(scene, s.renderer) == s.renderer
    assert resolve_settings(scene, Overrides(renderer="exact")).transfer.renderer == "exact"
    deeper = with_overrides(scene, render={"max_depth": scene.render.max_depth + 1})
    assert resolve_settings(deeper).transfer.max_depth == scene.render.max_depth + 1
    if scene.probe is not None:
        assert s.renderer == "exact"
        with pytest.raises(ValueError, match="renderer 'fast'"):
            resolve_settings(scene, Overrides(renderer="fast"))


def test_a_material_the_fast_path_has_not_verified_resolves_to_the_exact_path():
    """"auto" is the fast path on Fig. 4's diffuse cube and the exact path once the cube is a near-mirror metal
    (roughness below fast.MIN_ROUGHNESS), as the live page's edit re-resolves it (negative control: the same edit
    with --renderer fast keeps the fast path the user asked for)."""
    scene = load_scene(builtin_scene("fig4"))
    cube = scene.synthetic[0].model_dump(mode="json")
    mirror = with_overrides(scene, synthetic=[{**cube, "material": {"type": "metal", "roughness": 0.005}}])
    assert resolve_settings(scene).transfer.renderer == "fast"
    assert resolve_settings(mirror).transfer.renderer == "exact"
    assert resolve_settings(mirror, Overrides(renderer="fast")).transfer.renderer == "fast"


def test_every_setting_is_one_option_made_from_its_field():
    """Each field of Overrides but ``compare`` is an option of ``lft run`` (the live loop's simulator settings: of
    ``lft live``) whose flag, help and values are the field's (the command line, the page's validation and
    docs/cli.md read the same definition); an unknown setting is refused."""
    import typer.main
    from rich.markup import escape

    from lftransfer.app.cli import app
    from lftransfer.app.cli.options import setting_options

    commands = typer.main.get_command(app).commands
    params = {p.name: p for p in commands["live"].params}
    params.update({p.name: p for p in commands["run"].params})
    live_only = {"simulator", "simulator_threads", "simulator_nice", "renderer_threads"}
    assert live_only.isdisjoint(p.name for p in commands["run"].params)
    for f in dataclasses.fields(Overrides):
        if f.name == "compare":
            continue
        param = params[f.name]
        assert param.opts == [f.metadata["flag"] or "--" + f.name.replace("_", "-")], f.name
        assert " ".join(param.help.split()) == " ".join(escape(f.metadata["help"]).split()), f.name
        if f.metadata["choice"] is not None:
            assert param.metavar == "|".join(choices.values(f.metadata["choice"])), f.name
    group = setting_options("bounces", "renderer", "quiet_reference")
    asked = group(bounces=1, renderer="exact", quiet_reference=False)
    assert asked.overrides() == Overrides(bounces=1, renderer="exact")
    assert asked.arguments() == ["--bounces", "1", "--renderer", "exact"]
    judged = setting_options("quiet_reference", "reference_budget_s", defaults=(("quiet_reference", True),))
    assert judged().overrides() == Overrides(quiet_reference=True)
    assert judged(quiet_reference=False, reference_budget_s=90.0).arguments() == [
        "--no-quiet-reference", "--reference-budget", "90"]
    with pytest.raises(ValueError, match="not a setting"):
        setting_options("bounce")

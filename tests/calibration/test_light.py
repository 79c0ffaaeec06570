"""The point light step: boards lit by the real point light alone give its position (quarter resolution)."""

from __future__ import annotations

import numpy as np
import pytest

from lftransfer.scenes import quick_scene
from lftransfer.calibration.light import (LIGHT_BOARDS, LightError, black_share, board_samples, calibrate_light,
                                          count_light_messages, fit_light, light_board_poses)
from lftransfer.calibration.chart import chart_pose
from lftransfer.optics.geometry import project, rectangle_to_world
from lftransfer.rig.requests import Board, ViewCapture
from lftransfer.scenes import builtin_scene, load_scene, with_overrides
from lftransfer.sim.rig import SimRig
from lftransfer.sim.truth import hidden_world

SEED = 2


class _Spy:
    """A rig that passes every call on and keeps each view photograph with the set-up it was taken under."""

    def __init__(self, rig, strip_light: bool = False) -> None:
        self.rig, self.strip_light = rig, strip_light
        self.shots: list[tuple[Board, np.ndarray]] = []
        self.setups: list = []

    @property
    def info(self):
        return self.rig.info

    def setup(self, request) -> None:
        self.setups.append(request)
        if self.strip_light and isinstance(request, Board):     # an operator who forgot to switch the light on
            request = Board(centre=request.centre, normal=request.normal, size=request.size, albedo=request.albedo,
                            chart=request.chart)
        self.rig.setup(request)

    def project(self, image) -> None:
        self.rig.project(image)

    def capture_lf(self, request=None):
        return self.rig.capture_lf(request)

    def capture_view(self, request=ViewCapture()):
        frame = self.rig.capture_view(request)
        self.shots.append((self.setups[-1], frame.radiance))
        return frame

    def close(self) -> None:
        self.rig.close()


@pytest.fixture(scope="module")
def measured(variant):
    """The step on a rig with hidden truth (seed 2: the light 3.4 mm from the scene file's position), the boards
    held by the simulated operator a few millimetres and about a degree off; the true rig model stands for the
    calibrated one (the step uses only its projector's black level and cross-talk)."""
    scene = quick_scene(load_scene(builtin_scene("fig4")))
    world, truth = hidden_world(scene, SEED)
    sim = SimRig(world, truth=truth, operator_seed=SEED)
    spy = _Spy(sim)
    messages: list[str] = []
    fit, diag = calibrate_light(spy, truth, scene.synthetic_part(), progress=messages.append)
    return scene, world, truth, sim, spy, fit, diag, messages


def _samples(measured, where: str, subtract: bool = True):
    """Each board's samples from the fixture's photographs, the board taken where ``where`` says: "true" (the
    simulator's hidden pose), "measured" (its printed chessboard) or "asked" (the request)."""
    scene, _, truth, sim, spy, _, _, _ = measured
    view = scene.view
    share = black_share(truth.projector).astype(np.float32)
    out = []
    for k in range(len(spy.shots) // 2):
        (board, lit), (_, flood) = spy.shots[2 * k], spy.shots[2 * k + 1]
        image = lit - (flood - lit) * share if subtract else lit
        if where == "true":
            m = sim.boards_held[k].copy()
        elif where == "asked":
            m = rectangle_to_world(board.centre, board.normal, board.size)
        else:
            m, _ = chart_pose(lit, board.chart, view)
            if m[:3, 2] @ (np.asarray(view.origin) - m[:3, 3]) < 0:
                m[:3, 1:3] *= -1
        m[:3, :2] /= np.linalg.norm(m[:3, :2], axis=0)
        out.append(board_samples(image, view, m, board.size, board.chart))
    return out


def _error_mm(fit, world) -> float:
    return float(1000 * np.linalg.norm(fit.position - np.asarray(world.lights[0].position)))


def test_01_recovers_the_hidden_light(measured):
    """From the measured boards the light is 0.32 mm from where it really stands (bound 0.8 mm), from a scene file
    3.4 mm off; the model fits every pixel to 0.12 % RMS (bound 0.5 %), and the nuisances come out as built:
    intensity x albedo 2 x 0.8 W/sr, the chart's dark squares at a quarter of the board's albedo."""
    scene, world, _, sim, spy, fit, diag, messages = measured
    start = float(1000 * np.linalg.norm(np.asarray(scene.lights[0].position) - world.lights[0].position))
    assert start > 3.0
    assert _error_mm(fit, world) <= 0.8
    assert fit.residual_rms <= 0.005 and np.all(fit.std_mm < 0.05)
    np.testing.assert_allclose(fit.intensity_albedo, 2.0 * 0.8, rtol=0.01)
    assert fit.dark_ratio == pytest.approx(0.25, rel=0.02)
    assert fit.boards == LIGHT_BOARDS == len(diag["boards"]) == len(sim.boards_held)
    assert fit.pixels > 1000 * LIGHT_BOARDS
    assert all(isinstance(s, Board) and s.point_light and s.chart for s in spy.setups)
    assert len(spy.shots) == 2 * LIGHT_BOARDS                        # projector black, then white, per board
    assert len(messages) == count_light_messages(scene.synthetic_part()) == LIGHT_BOARDS + 1
    assert all(m.startswith("point light") for m in messages)


def test_02_the_fit_itself(measured):
    """With the boards where they really stand the fit is exact to 0.03 mm (bound 0.1 mm): what remains of the
    0.32 mm above is the printed chessboards' pose error at 256 x 192 view pixels."""
    _, world, _, _, _, _, _, _ = measured
    fit = fit_light(_samples(measured, "true"), measured[0].lights[0].position)
    assert _error_mm(fit, world) <= 0.1
    assert fit.residual_rms <= 0.002


def test_03_negative_controls(measured):
    """Measurably worse or refused: the boards taken where they were asked for (the operator's hand error left
    in) put the light 2.1 mm off (bound 1.5 mm); the projector's black level left in, 0.62 mm even with the true
    boards (bound 0.3 mm); one board alone is refused."""
    scene, world, _, _, _, fit, _, _ = measured
    good = _error_mm(fit, world)
    asked = fit_light(_samples(measured, "asked"), scene.lights[0].position)
    assert _error_mm(asked, world) >= max(3 * good, 1.5)
    unsubtracted = fit_light(_samples(measured, "true", subtract=False), scene.lights[0].position)
    assert _error_mm(unsubtracted, world) >= 0.3
    with pytest.raises(LightError, match="at least 2 boards"):
        fit_light(_samples(measured, "measured")[:1], scene.lights[0].position)


def test_04_poses_face_the_light_and_the_camera(measured):
    """The boards are asked for where the view camera sees their chessboard whole, facing the light and the camera,
    clear of the array; the same every time. A scene without a point light, or a view camera that sees nothing in
    front of the array, is refused with a message naming the step."""
    scene = measured[0].synthetic_part()
    poses = light_board_poses(scene)
    assert poses == light_board_poses(scene) and len(poses) == LIGHT_BOARDS
    light, eye = np.asarray(scene.lights[0].position), np.asarray(scene.view.origin)
    w, h = scene.view.resolution
    for b in poses:
        c, n = np.asarray(b.centre), np.asarray(b.normal)
        assert n @ (light - c) / np.linalg.norm(light - c) >= 0.5 and n @ (eye - c) / np.linalg.norm(eye - c) >= 0.5
        m = rectangle_to_world(c, n, b.size)
        corners = c + np.array([[sx, sy] for sx in (-1, 1) for sy in (-1, 1)]) @ m[:3, :2].T
        assert corners[:, 2].min() >= 0.015
        px = project(scene.view, corners)
        assert np.all((px >= 0) & (px <= [w - 1, h - 1]))
    normals = np.array([b.normal for b in poses])
    assert np.degrees(np.arccos(np.clip(normals @ normals.T, -1, 1))).max() > 30     # turned different ways
    with pytest.raises(LightError, match=r"point light: the scene has 0 point light\(s\)"):
        light_board_poses(load_scene(builtin_scene("fig5")).synthetic_part())
    away = with_overrides(scene, view={"origin": [0.55, 0.22, -0.3], "target": [0.0, 0.0, -0.3]})
    with pytest.raises(LightError, match=r"point light: only 0 board poses .* seen well"):
        light_board_poses(away)
    assert count_light_messages(load_scene(builtin_scene("fig5")).synthetic_part()) == 0


def test_05_a_dark_board_is_named(measured):
    """A board photographed with the point light off (the operator forgot it) stops the step with a message naming
    the board and what to check."""
    scene, world, truth, _, _, _, _, _ = measured
    sim = SimRig(world, truth=truth, operator_seed=SEED)
    with pytest.raises(LightError, match=r"point light: board 1 of \d at .* times as bright as .* is the point "
                                         r"light on"):
        calibrate_light(_Spy(sim, strip_light=True), truth, scene.synthetic_part())


class _AllLightsOn(_Spy):
    """An operator who leaves every point light on while the step asks for one."""

    def setup(self, request) -> None:
        if isinstance(request, Board) and request.light is not None:
            request = Board(centre=request.centre, normal=request.normal, size=request.size, albedo=request.albedo,
                            chart=request.chart, point_light=True)
        super().setup(request)


def test_06_several_lights_are_measured_one_by_one(variant):
    """A scene with two point lights: each is measured with its boards lit by it alone (the requests name it), both
    land within 0.8 mm of where they really stand (measured 0.33 and 0.27 mm; each hidden a few mm from the file's
    position), and the messages name them. Negative control: with both lights on for every board (an operator who
    does not switch the first one off) the fit lands about 10 cm away and is refused, naming the light."""
    scene = quick_scene(load_scene(builtin_scene("fig4")))
    scene = with_overrides(scene, lights=[*scene.lights, {"position": [0.22, -0.10, 0.02], "intensity": [1.5] * 3}])
    world, truth = hidden_world(scene, SEED)
    assert np.linalg.norm(np.subtract(world.lights[1].position, scene.lights[1].position)) > 1e-3
    spy = _Spy(SimRig(world, truth=truth, operator_seed=SEED))
    messages: list[str] = []
    fits = [calibrate_light(spy, truth, scene.synthetic_part(), light=i, progress=messages.append)[0] for i in (0, 1)]
    for i, fit in enumerate(fits):
        assert float(1000 * np.linalg.norm(fit.position - np.asarray(world.lights[i].position))) <= 0.8
    assert [s.light for s in spy.setups] == [0] * LIGHT_BOARDS + [1] * LIGHT_BOARDS
    assert len(messages) == count_light_messages(scene.synthetic_part()) == 2 * (LIGHT_BOARDS + 1)
    assert messages[0].startswith("point light 1: board 1") and messages[-1].startswith("point light 2: fit")
    with pytest.raises(ValueError, match="Board.light: the scene has 2 point light"):
        SimRig(world, truth=truth).setup(Board(centre=(0, 0, 0.1), normal=(0, 0, -1), point_light=True, light=2))
    sloppy = _AllLightsOn(SimRig(world, truth=truth, operator_seed=SEED))
    with pytest.raises(LightError, match=r"point light 2: the fit puts it \d+ mm from the scene file's position "
                                         r"\(0.22, -0.1, 0.02\) m .* the only light on\?"):
        calibrate_light(sloppy, truth, scene.synthetic_part(), light=1)

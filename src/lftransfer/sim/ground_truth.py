"""The path-traced ground truth of a simulated world (docs/architecture.md, "Verification").

The ground truth is the union scene (real objects + synthetic objects + point light or the room's light, no lens
array) path traced from the view camera with Mitsuba's ``path`` integrator; the real-alone and synthetic-alone scenes
are rendered with the same seeds so that their noise cancels in the cross-transfer term (in a lit room, each alone
as the rig lights it before any exchange: ``_room``). Two independent seeds give the ground truth's own noise.
Renders are cached under a hash of everything they depend on, each entry with its checksum
(:mod:`lftransfer.sim.gt_cache`). It renders the hidden world: the faces reach it through
:class:`lftransfer.sim.oracle.Oracle`.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from lftransfer.render.camera import sensor_dict
from lftransfer.render.shapes import scene_dict
from lftransfer.sim.gt_cache import CacheProblem, read_entry, write_entry

__all__ = ["GT_MAX_DEPTH", "GroundTruth", "lightfield_depths", "render_ground_truth", "single_seed", "true_depths",
           "view_distances", "views_overlap"]

GT_MAX_DEPTH = 12  # Mitsuba path depth (counts the segment to the emitter): far beyond what transfer keeps


@dataclass
class GroundTruth:
    """Ground-truth view images, each rendered with two independent seeds.

    Attributes:
        union: (2, H, W, 3) float32, all objects together.
        real: (2, H, W, 3) float32, real objects alone.
        synthetic: (2, H, W, 3) float32, synthetic objects alone.
        alpha_real, alpha_synthetic: (H, W) float32 coverage of each set of objects.
        depth_real, depth_synthetic: (H, W) float32 distance from the view camera's centre to each set of objects
            along each pixel's ray (the mean over the rays that hit), metres, inf where none; None where the view
            camera cannot see one set in front of the other (:func:`views_overlap`).
    """

    union: np.ndarray
    real: np.ndarray
    synthetic: np.ndarray
    alpha_real: np.ndarray
    alpha_synthetic: np.ndarray
    depth_real: np.ndarray | None = None
    depth_synthetic: np.ndarray | None = None

    @property
    def image(self) -> np.ndarray:
        """(H, W, 3) the ground truth: the mean of the two union renders."""
        return self.union.mean(axis=0)

    def _nearer(self, near: np.ndarray | None, far: np.ndarray | None) -> np.ndarray:
        """(H, W) bool: pixels where both depths are seen and ``near`` is the nearer (none without depths)."""
        if near is None or far is None:
            return np.zeros(self.alpha_real.shape, bool)
        return np.isfinite(near) & np.isfinite(far) & (near < far)

    @property
    def real_in_front(self) -> np.ndarray:
        """(H, W) bool: pixels where a real object hides a synthetic one (both seen, the real one nearer)."""
        return self._nearer(self.depth_real, self.depth_synthetic)

    @property
    def synthetic_in_front(self) -> np.ndarray:
        """(H, W) bool: pixels where a synthetic object hides a real one (both seen, the synthetic one nearer)."""
        return self._nearer(self.depth_synthetic, self.depth_real)

    @property
    def synthetic_seen(self) -> np.ndarray:
        """(H, W) float32 how much of each pixel shows a synthetic object: its coverage, less the part a real object
        in front of it covers."""
        hidden = np.where(self.real_in_front, np.clip(self.alpha_real, 0.0, 1.0), 0.0)
        return (self.alpha_synthetic * (1.0 - hidden)).astype(np.float32)

    def composite_alone(self, i: int) -> np.ndarray:
        """(H, W, 3) seed ``i``'s real-alone and synthetic-alone renders put together as the view camera would see
        both without any light between them: the nearer in front of the farther, each seen through the part of the
        pixel it leaves uncovered (exact but where both cover part of a pixel in different orders)."""
        from lftransfer.composite import composite

        over = composite(self.synthetic[i], self.alpha_synthetic, self.real[i])
        front = self.real_in_front
        if not front.any():
            return over
        under = composite(self.real[i], self.alpha_real, self.synthetic[i])       # the real objects in front
        return np.where(front[..., None], under, over).astype(np.float32)


def _inputs_hash(scene, spp: int, seeds: tuple[int, ...], crop: tuple[int, int, int, int] | None = None) -> str:
    """SHA-256 (hex) of everything the ground-truth renders depend on."""
    import mitsuba

    def objects(objs):
        out = []
        for o in objs:
            d = o.model_dump(mode="json")
            if getattr(o, "file", None):
                d["file_sha"] = hashlib.sha256(Path(o.file).read_bytes()).hexdigest()
            out.append(d)
        return out

    payload = {
        "real": objects(scene.real), "synthetic": objects(scene.synthetic),
        # one light hashes as the single table it was before several were possible (cached entries stay valid)
        "light": _lights_key(scene.lights), "view": scene.view.model_dump(mode="json"),
        "spp": spp, "seeds": list(seeds), "depth": GT_MAX_DEPTH, "mitsuba": mitsuba.__version__, "v": 1,
    }
    if crop is not None:                     # whole frames hash as they did before crops existed
        payload["crop"] = list(crop)
    if len(_light_groups(scene)) > 1:          # one light source hashes as before the sources were rendered apart
        payload["light_groups"] = 1
    env = getattr(scene, "environment", None)
    if env is not None:                      # scenes in a dark room hash as they did before rooms had light
        payload["environment"] = {**env.model_dump(mode="json"), "v": 2}
        if env.file is not None:
            payload["environment"]["file_sha"] = hashlib.sha256(Path(env.file).read_bytes()).hexdigest()
    return hashlib.sha256(json.dumps(payload, sort_keys=True).encode()).hexdigest()


def _lights_key(lights) -> dict | list | None:
    # a point light's ``kind`` is left out: entries cached before lights had one stay valid
    dumps = [lt.model_dump(mode="json", exclude={"kind"}) for lt in lights]
    return None if not dumps else dumps[0] if len(dumps) == 1 else dumps


def _light_groups(scene) -> list[tuple[list, bool]]:
    """The light sources the ground truth renders one at a time, whose images it adds: (the point lights, whether
    the emitting objects emit) per render. Path tracing picks one source per light sample, so a scene lit by point
    lights and emitting objects together gets the noise of that choice on every lit surface, which the renders of
    each side alone, lit by fewer sources, do not share: on the cross term it is many times the noise of one source.
    Transport is linear in the sources, so the sum is the same image. One render where there is one source."""
    lights = list(scene.lights)
    emitters = any(o.material.type == "emitter" for o in scene.synthetic)
    if not (lights and emitters) and len(lights) <= 1:
        return [(lights, True)]
    return [([lt], False) for lt in lights] + ([([], True)] if emitters else [])


def _dark(objects) -> list:
    """``objects`` with every emitting one's light switched off (its shape stays, black: an emitter's surface)."""
    from lftransfer.scenes.models import DiffuseMaterial

    black = DiffuseMaterial(albedo=[0.0, 0.0, 0.0])
    return [o.model_copy(update={"material": black}) if o.material.type == "emitter" else o for o in objects]


STACK_CHANNELS = 20     # union, real, synthetic x 2 seeds x RGB, then the real and synthetic alphas


def render_ground_truth(scene, *, spp: int = 256, seeds: tuple[int, int] = (1, 2), use_cache: bool = True,
                        progress: Callable[[str], None] | None = None,
                        warn: Callable[[str], None] | None = None,
                        crop: tuple[int, int, int, int] | None = None) -> GroundTruth:
    """Path trace the union, real-alone and synthetic-alone scenes from the view camera.

    Args:
        scene: ``lftransfer.scenes.SceneConfig`` (its ``real`` objects are the hidden truth).
        spp: samples per pixel of each render.
        seeds: the two independent seeds.
        crop: (x, y, width, height) of the view's pixels to render (the film's crop window, so the samples go
            there only); None: the whole frame. The images are of the crop's size.
        use_cache: read and write the cache (:mod:`lftransfer.sim.gt_cache`); an entry that fails its checks is
            rendered again and replaced.
        progress: called before each render.
        warn: called with one line when a cache entry is bad.

    Returns:
        GroundTruth.
    """
    from lftransfer.backend import mitsuba

    w, h = scene.view.resolution
    inputs = _inputs_hash(scene, spp, seeds, crop)
    shape = (h, w) if crop is None else (crop[3], crop[2])
    depths = true_depths(scene, crop) if views_overlap(scene) else None
    if use_cache:
        cached = read_entry(inputs, (*shape, STACK_CHANNELS))
        if isinstance(cached, np.ndarray):
            return _unpack(cached, depths)
        if isinstance(cached, CacheProblem) and warn is not None:
            warn(cached.message())
    mi = mitsuba()
    view = scene.view
    sensor = sensor_dict(view.origin, view.target, view.up, view.fov_deg, w, h, spp=spp)
    if crop is not None:
        x, y, cw, ch = map(int, crop)
        if not (0 <= x and 0 <= y and cw >= 1 and ch >= 1 and x + cw <= w and y + ch <= h):
            raise ValueError(f"crop {crop} is not inside the {w} x {h} view")
        sensor["film"].update(crop_offset_x=x, crop_offset_y=y, crop_width=cw, crop_height=ch)
    extra = {"sensor": sensor,
             "integrator": {"type": "path", "max_depth": GT_MAX_DEPTH, "hide_emitters": False}}
    room = _room(scene)
    groups = _light_groups(scene)
    images: dict[str, list[np.ndarray]] = {}
    for name, objs in (("union", scene.real + scene.synthetic), ("real", scene.real), ("synthetic", scene.synthetic)):
        shapes = dict(extra)
        if room is not None:
            shapes.update(room[name])
        mscenes = [mi.load_dict(scene_dict(objs if emit else _dark(objs), extra={**shapes, **_point_lights(lights)}),
                                parallel=False, optimize=False) for lights, emit in groups]
        images[name] = []
        for seed in seeds:
            if progress:
                progress(f"ground truth: {name}, seed {seed}")
            rendered = [np.array(mi.render(m, spp=spp, seed=seed), dtype=np.float32) for m in mscenes]
            image = rendered[0]
            for more in rendered[1:]:                 # the sources' light adds; the coverage is the same
                image[..., :3] += more[..., :3]
            images[name].append(image)
    alpha_real = images["real"][0][..., 3:4]
    if room is not None:        # the room seen behind the real objects counts as covered in Mitsuba's alpha
        alpha_real = _cropped(np.asarray(_objects_view(scene.real, view).alpha, np.float32), crop)[..., None]
    stack = np.concatenate([images[n][i][..., :3] for n in ("union", "real", "synthetic") for i in range(2)]
                           + [alpha_real, images["synthetic"][0][..., 3:4]], axis=-1)
    if use_cache:
        write_entry(inputs, stack)
    return _unpack(stack, depths)


DEPTH_SPP = 16     # rays per pixel of the true depths


def _point_lights(lights) -> dict[str, dict]:
    """Mitsuba dicts of point lights, named as the ground truth names them."""
    return {("point_light" if i == 0 else f"point_light_{i}"):
            {"type": "point", "position": list(map(float, lt.position)),
             "intensity": {"type": "rgb", "value": list(map(float, lt.intensity))}}
            for i, lt in enumerate(lights)}


def _room(scene) -> dict[str, dict] | None:
    """Per render ("union", "real", "synthetic"), the Mitsuba dicts of the room's light (``[environment]``), or
    None in a dark room. The union sees and is lit by the whole room. Each scene alone stands as the system gives
    it light before any exchange, so that the cross term C_gt is what the array carries (the other objects' light
    and the room seen past them):
    - the real objects alone: the lens array (its nominal rectangle, an absorber) blocks the room behind it, as
      the rig's panel does with the projector black (the transfer later projects the room within the lenslets'
      window only);
    - the synthetic objects alone: lit by the room but for the directions the lenslets record (|u|, |v| <= a
      towards +z, zeroed in the map), which reach them through the array; the light probe gives them the rest
      (:class:`~lftransfer.render.lights.EnvironmentLight`'s blocker). The camera does not see the room in this
      render (it is composited over the real one, which shows it)."""
    env = getattr(scene, "environment", None)
    if env is None:
        return None
    from lftransfer.backend import mitsuba
    from lftransfer.optics.geometry import env_directions, in_window
    from lftransfer.render.shapes import lens_array_absorber
    from lftransfer.rig.model import nominal_rig

    mi = mitsuba()
    radiance = env.radiance_map()
    array = nominal_rig(scene.rig).array
    d = env_directions(radiance.shape[1], radiance.shape[0])
    window = (d[..., 2] > 0) & in_window(d, array.half_width)
    emitter = {"type": "envmap", "bitmap": mi.Bitmap(radiance)}
    outside = {"type": "envmap", "bitmap": mi.Bitmap(np.where(window[..., None], 0.0, radiance).astype(np.float32))}
    return {"union": {"room": emitter},
            "real": {"room": emitter, "lens_array_absorber": lens_array_absorber(array)},
            "synthetic": {"room": outside,
                          "integrator": {"type": "path", "max_depth": GT_MAX_DEPTH, "hide_emitters": True}}}


def _cropped(image: np.ndarray, crop: tuple[int, int, int, int] | None) -> np.ndarray:
    """The ``crop`` (x, y, width, height) of an (H, W, ...) image; the image itself where None."""
    if crop is None:
        return image
    x, y, cw, ch = map(int, crop)
    return image[y:y + ch, x:x + cw]


def views_overlap(scene) -> bool:
    """Whether the view camera can see a real object in front of a synthetic one, or the reverse: only from off the
    array's plane (a ray from a camera in the plane stays on one side of it; the built-in paper scenes' cameras
    stand there), or wherever it stands with several interfaces (it cannot stand in all their planes)."""
    return bool(scene.real) and bool(scene.synthetic) and (bool(scene.interfaces)
                                                           or abs(float(scene.view.origin[2])) > 1e-9)


def view_distances(objects, view, spp: int = DEPTH_SPP) -> np.ndarray:
    """(H, W) float32 distance from the view camera's centre to ``objects`` along each pixel's ray (the mean over
    ``spp`` rays of those that hit), metres; inf where none hits."""
    return np.asarray(_objects_view(objects, view, spp).depth, np.float32)


def _objects_view(objects, view, spp: int = DEPTH_SPP):
    """The view camera's render of ``objects`` without lights (``ViewImage``: their coverage and distances)."""
    from lftransfer.backend import mitsuba
    from lftransfer.render.camera import sensor_dict
    from lftransfer.render.renderer import HalfSpaceRenderer

    w, h = view.resolution
    sensor = mitsuba().load_dict(sensor_dict(view.origin, view.target, view.up, view.fov_deg, w, h, spp=spp))
    return HalfSpaceRenderer(list(objects), max_depth=1).render_view(sensor, w, h, [], spp=spp)


def lightfield_depths(world, model, U: int, V: int, *, time_s: float = 0.0) -> np.ndarray:
    """(K, V, U) float64 depth of the real objects along each light field entry's centre ray, as a rig model
    defines the entries (its lens array, in the array frame it places in the world), metres along the array's
    normal: what :func:`~lftransfer.transfer.projection.measure_depth` measures, without its error. NaN off the
    data samples and where the ray meets no real object."""
    from lftransfer.lightfield import LightField
    from lftransfer.render.base import lightfield_rays
    from lftransfer.render.renderer import HalfSpaceRenderer
    from lftransfer.scenes.frame import scene_in_frame

    posed = scene_in_frame(world.at(time_s), model.world_to_array())
    array = model.array
    origins, directions = lightfield_rays(array, U, V, side="real", area=False, spp=1)
    _, hit, dist = HalfSpaceRenderer(list(posed.real), max_depth=1).render_rays(origins, directions, [])
    z = np.where(hit, dist.astype(np.float64) * directions[:, 2], np.nan).reshape(array.K, V, U)
    return np.where(LightField.zeros(array, U, V).mask()[None], z, np.nan)


def true_depths(scene, crop: tuple[int, int, int, int] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(H, W) float32 distances from the view camera's centre to the real objects and to the synthetic objects
    (:func:`view_distances`); of the ``crop`` (x, y, width, height) only where given."""
    return _cropped(view_distances(scene.real, scene.view), crop), \
        _cropped(view_distances(scene.synthetic, scene.view), crop)


def _unpack(stack: np.ndarray, depths: tuple[np.ndarray, np.ndarray] | None = None) -> GroundTruth:
    parts = [stack[..., 3 * i:3 * i + 3] for i in range(6)]
    return GroundTruth(union=np.stack(parts[0:2]), real=np.stack(parts[2:4]), synthetic=np.stack(parts[4:6]),
                       alpha_real=stack[..., 18], alpha_synthetic=stack[..., 19],
                       depth_real=None if depths is None else depths[0],
                       depth_synthetic=None if depths is None else depths[1])


def single_seed(gt: GroundTruth, i: int) -> GroundTruth:
    """The ground truth of seed ``i`` (0 or 1) alone, in both slots (its own noise then reads as 0)."""
    pick = lambda x: np.stack([x[i], x[i]])  # noqa: E731
    return dataclasses.replace(gt, union=pick(gt.union), real=pick(gt.real), synthetic=pick(gt.synthetic))

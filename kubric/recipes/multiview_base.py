"""The static-scene, many-view pipeline shared by ``klevr``, ``toybox``, ``texture_nerf``,
``robust_nerf``, ``multiview_matting`` and ``nvs`` (the paper's multi-view challenges).

One scene = one seed (every random number from ``numpy.random.RandomState(seed)``, in a fixed
order). A scene is **static** and seen from ``num_views`` cameras; the views are the frames
``0 .. num_views − 1`` of one render with the camera keyframed at every frame, so Blender writes
every layer of every view at once and view ``i`` is the file ``*_{i:05d}.*``. Steps:

1. ``open_sources``: asset sources (KuBasic; HDRIs / a mesh collection for some recipes);
2. ``build_background``: floor (the KuBasic dome: floor at z = 0), lights, backdrop;
3. ``add_objects``: objects standing **upright** on the floor (random turn about z), placed by
   rejection sampling so that their footprint circles (radius = the largest horizontal distance
   of their scaled bounding box from their origin) do not overlap; an object with no free place
   after 1000 tries is left out (counted in ``metadata.dropped_objects``);
4. ``camera_positions``: one camera position per view (default: uniform on the sphere cap of
   radius ``camera_distance`` and elevation ``elevation_range`` around the look-at point), the
   camera keyframed at each view's frame looking at ``look_at``;
5. ``animate``: per-view changes (``robust_nerf``'s impostors);
6. render (RGB at ``samples``; exact depth, instance segmentation, normal and object coordinates);
7. write the layers, ``metadata.json`` (instances ordered by visible pixels over all views, as
   MOVi), an empty ``events.json`` (nothing moves, nothing collides), the recipe's extra layers and
   files, and the camera export ``transforms_{train,val,test}.json``
   (:mod:`kubric.datasets.exports.nerf`).

Scene metadata added by this family: ``num_views``, ``views`` (per view: ``split``),
``split_ratio``, ``splits`` (``{split: [view, ...]}``), ``look_at``, ``dropped_objects``.
"""

from __future__ import annotations

import abc
import dataclasses
import math
import pathlib
import tempfile

import numpy as np

import kubric as kb
from kubric import asset_tools
from kubric.core import camera_geometry as geo
from kubric.datasets.exports import nerf
from kubric.io.layers import LAYERS
from kubric.io.scene_writer import write_scene
from kubric.pipeline import Option, OptionError, Recipe, float_range, resolution
from kubric.recipes import extra_layers as extra
from kubric.recipes.common import (
    annotate_instances,
    check_min_max,
    check_source_options,
    kubasic_sources,
    scene_documents,
    source_location,
)
from kubric.recipes.common import open_existing_source as open_source
from kubric.recipes.lens_options import LensOptions
from kubric.recipes.movi import add_clevr_lights
from kubric.recipes.movi_base import new_camera
from kubric.recipes.render_quality import RenderQuality

#: layers every multi-view scene writes (no flow: the views are not a motion sequence)
RENDERED_LAYERS = ("rgba", "depth", "segmentation", "normal", "object_coordinates")
#: per-view file names added to every frame entry of the transforms files
VIEW_FILES = {f"{name}_file": LAYERS[name].template for name in RENDERED_LAYERS if name != "rgba"}
#: the HDRI dome shows the HDRI ground-projected from this height (m), as MOVi-C
HDRI_PROJECTION_HEIGHT = 2.0


def footprint_radius(obj) -> float:
    """Largest horizontal distance of the object's scaled bounding box corners from its origin
    (the radius its footprint sweeps when turned about z)."""
    b = np.asarray(obj.bounds, np.float64) * np.asarray(obj.scale, np.float64)
    corners = np.array([[x, y] for x in b[:, 0] for y in b[:, 1]])
    return float(np.max(np.linalg.norm(corners, axis=1)))


def stand_upright(obj, xy, yaw: float) -> None:
    """Put ``obj`` on the floor (z = 0) at ``xy``, turned by ``yaw`` about z."""
    low_z = float(np.asarray(obj.bounds)[0, 2] * np.asarray(obj.scale)[2])
    obj.quaternion = kb.Quaternion(axis=(0.0, 0.0, 1.0), angle=float(yaw))
    obj.position = (float(xy[0]), float(xy[1]), -low_z)


def free_place(rng, occupied: list, radius: float, half_extent: float, margin: float = 0.05,
               max_trials: int = 1000):
    """Rejection-sample a floor position in the square ``±half_extent`` whose circle of
    ``radius`` (plus ``margin``) touches no ``(xy, radius)`` of ``occupied``; returns (xy, random
    yaw) and appends the circle to ``occupied``, or None after ``max_trials``."""
    for _ in range(max_trials):
        xy = rng.uniform(-half_extent, half_extent, 2)
        yaw = float(rng.uniform(0.0, 2.0 * math.pi))
        if all(np.linalg.norm(xy - c) >= radius + r + margin for c, r in occupied):
            occupied.append((xy, radius))
            return xy, yaw
    return None


def place_upright(obj, rng, occupied: list, half_extent: float) -> bool:
    """Stand ``obj`` at a :func:`free_place` for its footprint; False when there is none."""
    place = free_place(rng, occupied, footprint_radius(obj), half_extent)
    if place is None:
        return False
    stand_upright(obj, *place)
    return True


def kubasic_object(sources, shape: str, size: float, rng):
    """A KuBasic shape at scale ``size`` with a random-hue diffuse material (metadata: ``size``,
    ``color``)."""
    color = kb.random_hue_color(rng=rng)
    obj = sources["kubasic"].create(shape, scale=size)
    obj.material = kb.PrincipledBSDFMaterial(color=color, roughness=0.6)
    obj.metadata = {**obj.metadata, "size": float(size),
                    "color": np.asarray(color.rgb, np.float32)}
    return obj


def sized_object(source, asset_id: str, size: float):
    """An asset of ``source`` scaled so that its largest bounding-box extent is ``size`` m
    (metadata ``size``)."""
    obj = source.create(asset_id)
    bounds = np.asarray(obj.bounds, np.float64)
    obj.scale = size / max(float(np.max(bounds[1] - bounds[0])), 1e-9)
    obj.metadata = {**obj.metadata, "size": float(size)}
    return obj


def open_hdri_source(path):
    """The HDRI source at ``path``, or the HDRIs shipped with bpy when None."""
    return asset_tools.ensure_hdri_source() if path is None else open_source(path, "hdri_source")


def sphere_cap_positions(rng, count: int, distance, elevation_deg, target) -> np.ndarray:
    """(count, 3) points uniform (by area) on the sphere cap around ``target``: radius
    U(distance), elevation between ``elevation_deg`` (degrees above the horizon)."""
    lo, hi = (math.sin(math.radians(e)) for e in elevation_deg)
    out = np.zeros((count, 3))
    for i in range(count):
        r = rng.uniform(*distance)
        s = rng.uniform(lo, hi)
        phi = rng.uniform(0.0, 2.0 * math.pi)
        c = math.sqrt(max(0.0, 1.0 - s * s))
        out[i] = np.asarray(target) + r * np.array([c * math.cos(phi), c * math.sin(phi), s])
    return out


def orbit_positions(count: int, distance: float, elevation_deg: float, target,
                    phase: float = 0.0) -> np.ndarray:
    """(count, 3) evenly spaced positions on a horizontal circle around ``target``."""
    e = math.radians(elevation_deg)
    phi = phase + 2.0 * math.pi * np.arange(count) / count
    rel = distance * np.stack([math.cos(e) * np.cos(phi), math.cos(e) * np.sin(phi),
                               np.full(count, math.sin(e))], axis=1)
    return np.asarray(target, np.float64) + rel


def flag_mask(layers: dict, instances: list, flag: str) -> np.ndarray:
    """A 0/1 mask per view (T, H, W, 1) uint8: 1 where the segmentation shows an instance whose
    metadata ``flag`` is true (e.g. ``is_salient``, ``is_impostor``)."""
    lut = np.zeros(len(instances) + 1, np.uint8)
    for k, info in enumerate(instances, start=1):
        lut[k] = bool(info[flag])
    return lut[layers["segmentation"]]


@dataclasses.dataclass
class ExtraOutputs:
    """A multi-view recipe's own outputs: ``layers`` (each declared in its schema; the
    transforms files' frame entries get ``<layer>_file`` with the schema's template),
    ``files`` (other files of the scene directory, e.g. ``points.npz``)."""

    layers: dict[str, np.ndarray] = dataclasses.field(default_factory=dict)
    files: dict[str, object] = dataclasses.field(default_factory=dict)


class MultiviewBase(RenderQuality, Recipe, LensOptions):
    """Common options and steps of the multi-view recipes (not registered itself)."""

    resolution = Option((128, 128), "(width, height) in pixels: N or WxH", type=resolution)
    num_views = Option(32, "number of camera views (frames 0 .. num_views-1)", low=1, high=10000)
    split_ratio = Option((8, 1, 1), "train,val,test weights: view v is split by v mod "
                         "(train+val+test) (see transforms_*.json)", type=nerf.split_ratio)
    camera_distance = Option((9.0, 11.0), "camera distance (m) from the look-at point, low,high",
                             type=float_range, low=0.1)
    elevation_range = Option((20.0, 70.0), "camera elevation above the horizon (degrees), "
                             "low,high", type=float_range, low=-89.0, high=89.9)
    kubasic_source = Option(None, "KuBasic asset source folder or URL (default: built locally)",
                            type=source_location)
    extra_layers = Option((), "opt-in ground truth per view: comma-separated "
                          f"{', '.join(extra.STATIC_EXTRA_LAYERS)} (docs/conventions.md)",
                          type=extra.static_extra_layers)

    # ------------------------------------------------------------------ checks
    def check(self) -> None:
        message = nerf.check_views(self.name, self.num_views, self.split_ratio)
        if message:
            raise OptionError(message)
        check_source_options(self, names=("objects",))
        check_min_max(self)
        self.check_lens()
        rational = [v for values in (self.lens_coefficients, self.lens_coefficients_high)
                    for v in (values or ())[5:] if v]
        if self.lens == "opencv" and rational:
            raise OptionError(f"{self.name}: the NeRF transforms (nerfstudio's OPENCV model) have "
                              f"no k4, k5, k6; got {rational} (give k1,k2,p1,p2[,k3])")
        self.check_renderer()

    def renderer_requests(self) -> dict[str, str]:
        return {**super().renderer_requests(), **self.lens_requests()}

    def prepare(self) -> None:
        self.open_sources()

    # ------------------------------------------------------------------ steps
    def open_sources(self) -> dict:
        return kubasic_sources(self.kubasic_source)

    @abc.abstractmethod
    def build_background(self, scene, rng, sources) -> str:
        """Add floor / lights / backdrop; return the background description for the metadata."""

    @abc.abstractmethod
    def add_objects(self, scene, rng, sources) -> None:
        """Add the static objects."""

    def add_upright(self, scene, obj, rng, occupied: list, half_extent: float) -> bool:
        """Add ``obj`` standing at a free place (:func:`place_upright`), or count it in
        ``metadata.dropped_objects`` when there is none."""
        if place_upright(obj, rng, occupied, half_extent):
            scene.add(obj)
            return True
        scene.metadata["dropped_objects"] += 1
        return False

    def look_at(self) -> tuple[float, float, float]:
        return (0.0, 0.0, 0.0)

    def camera_positions(self, rng) -> np.ndarray:
        return sphere_cap_positions(rng, self.num_views, self.camera_distance,
                                    self.elevation_range, self.look_at())

    def animate(self, scene, rng, splits: list[str], sources) -> None:
        """Per-view changes after the camera is keyed (default: none)."""
        return None

    def finish_scene(self, scene, seed: int) -> None:
        """After the objects are placed, before the camera is keyed (default: nothing)."""

    def add_floor(self, scene, sources, material):
        """The KuBasic dome (floor disc at z = 0 bending up into a wall) as the background."""
        dome = sources["kubasic"].create("dome", name="dome", static=True, background=True)
        dome.material = material
        scene.add(dome)
        return dome

    def grey_background(self, scene, rng, sources, color="gray") -> str:
        """A diffuse dome of ``color`` lit by the CLEVR lamps (as MOVi-A); returns the hex."""
        floor = kb.get_color(color)
        self.add_floor(scene, sources, kb.PrincipledBSDFMaterial(color=floor, roughness=1.0,
                                                                 specular=0.0))
        add_clevr_lights(scene, rng)
        return floor.hexstr

    def hdri_background(self, scene, rng, sources) -> str:
        """A random HDRI of ``sources["hdri"]`` lights the scene and shows behind it; the dome
        shows it ground-projected (a FlatMaterial invisible to non-camera rays, as MOVi-C).
        Returns the HDRI id."""
        source = sources["hdri"]
        hdri_ids = source.all_asset_ids
        hdri_id = hdri_ids[rng.randint(len(hdri_ids))]
        hdri = source.create(hdri_id, mapping="environment")
        scene.background = hdri
        scene.ambient_illumination = hdri
        ground = source.create(hdri_id, mapping="environment",
                               projection_height=HDRI_PROJECTION_HEIGHT)
        self.add_floor(scene, sources, kb.FlatMaterial(color=ground, indirect_visibility=False))
        return hdri_id

    def renderer_options(self) -> dict:
        """Extra keyword arguments of :class:`kubric.renderer.Blender` (also recorded in
        ``metadata.renderer``). Default: none."""
        return {}

    def extra_outputs(self, scene, layers, instances, meta) -> ExtraOutputs:
        """The recipe's own layers and files (``meta``, the scene metadata, may get fields).
        Default: none."""
        return ExtraOutputs()

    # ------------------------------------------------------------------ the pipeline
    def key_camera(self, scene, positions) -> None:
        camera = new_camera()  # MOVi's lens and sensor
        scene.camera = camera
        for frame, position in zip(scene.frames, positions, strict=True):
            camera.position = position
            camera.look_at(self.look_at())
            camera.keyframe_insert("position", frame)
            camera.keyframe_insert("quaternion", frame)

    def generate(self, seed: int, out_dir: pathlib.Path) -> None:
        rng = np.random.RandomState(seed)
        sources = self.open_sources()
        scene = kb.Scene(resolution=self.resolution, frame_start=0,
                         frame_end=self.num_views - 1)
        scene.metadata["dropped_objects"] = 0
        splits = nerf.view_splits(self.num_views, self.split_ratio)
        with tempfile.TemporaryDirectory(prefix=f"kubric_{self.name}_") as scratch:
            self.scratch = pathlib.Path(scratch)  # for generated files (meshes, textures)
            background = self.build_background(scene, rng, sources)
            self.add_objects(scene, rng, sources)
            self.finish_scene(scene, seed)  # material_source= (toybox)
            self.key_camera(scene, self.camera_positions(rng))
            self.animate(scene, rng, splits, sources)
            scene.camera.lens = self.make_lens(rng)  # drawn after the rest (lens_options)
            renderer = kb.renderer.create(self.renderer, scene, self.scratch / "render",
                                          **self.renderer_settings(**self.renderer_options()))
            layers = renderer.render(return_layers=RENDERED_LAYERS)
        render_settings = self.render_metadata(renderer)
        self.write_outputs(scene, layers, seed, out_dir, background, render_settings, splits)

    def write_outputs(self, scene, layers, seed, out_dir, background, render_settings,
                      splits) -> list:
        candidates = [a for a in scene.foreground_assets if isinstance(a, kb.PhysicalObject)]
        rendered = set(layers)
        extra.add_before_relabel(scene, layers, self.extra_layers)
        visible = annotate_instances(scene, layers, candidates)
        extra.add_after_relabel(scene, layers, self.extra_layers, visible)
        schema = extra.schema_with(self.schema, self.extra_layers)
        by_split = {s: [v for v, name in enumerate(splits) if name == s]
                    for s in nerf.SPLITS}
        metadata, events = scene_documents(
            self, scene, seed, visible, background=background, renderer=render_settings,
            num_views=self.num_views, views=[{"split": s} for s in splits],
            split_ratio=list(self.split_ratio), splits=by_split, look_at=list(self.look_at()))
        own = self.extra_outputs(scene, layers, metadata["instances"], metadata["metadata"])
        view_files = dict(VIEW_FILES)
        view_files.update({f"{name}_file": schema.layer_formats[name].template
                           for name in (*own.layers, *(n for n in layers if n not in rendered))})
        depth = layers["depth"][layers["depth"] < geo.BACKGROUND_DEPTH]
        near, far = (float(depth.min()), float(depth.max())) if depth.size else (0.0, 0.0)
        transforms = nerf.nerf_transforms(
            scene.camera, list(scene.frames), scene.resolution, splits, view_files,
            extra={"recipe": self.name, "seed": int(seed), "near": near, "far": far,
                   "split_ratio": list(self.split_ratio)})
        files = {**own.files, **{f"transforms_{split}.json": data
                                 for split, data in transforms.items()}}
        write_scene(schema, out_dir, {**layers, **own.layers}, metadata, events, files=files)
        return visible

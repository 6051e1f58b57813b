"""``vbr``: the paper's video-based reconstruction challenge (LASR, Yang et al. 2021): one object
moves and spins in front of the camera; the scene directory holds RGB and the exact layers
(silhouette = segmentation, forward / backward flow, depth, ...) and a ready-to-train LASR
sequence in ``lasr/`` (:mod:`kubric.datasets.exports.lasr`).

The object floats (gravity 0, no floor): **rigid** is a KuBasic shape (or an asset of
``objects_source``, e.g. a ShapeNet build) with a random-hue material; **articulated** is a
multi-link URDF of ``pybullet_data`` (:mod:`kubric.recipes.articulated_models`; or
``urdf_file``) whose links are simulated with passive joints and rendered, one instance per link;
**character** (only when asked for: ``object_type=character``) is a person from
``character_source`` performing a clip from ``motion_source`` (:func:`kubric.recipes.people.
add_person`; default the MakeHuman humans source, ``procedural`` the built-in tube person), one
instance with its COCO keypoints in the metadata (docs/characters.md), moved by keys that follow
the same free flight (it is kinematic); ``object_model`` is ``<character id>/<clip id>``.
It is scaled so that its largest extent (articulated: in the rest pose) is ``object_size``, turned
randomly, given a speed U(``speed_range``) in a random direction and an angular velocity of
U(``spin_range``) rad/s about a random axis, and placed so that its centre passes the origin
half-way through the video. PyBullet simulates frames 0 .. ``num_frames`` + 1 (so flow is defined
at both ends) and Blender renders frames 1 .. ``num_frames`` (files ``*_{i:05d}`` with
i = 0 .. ``num_frames`` − 1). The camera (MOVi's 35 mm lens, 32 mm sensor) stands at
U(``camera_distance``) m from the origin at an elevation of U(10°, 50°) and either looks at the
origin (``camera=static``) or turns every frame to look at the object's centre
(``camera=follow``). Background: a plain colour of random hue; CLEVR lamps.

Every part of the object is an instance, even one never visible (instances ordered by visible
pixels). Metadata: ``object_type`` (``rigid`` / ``articulated``), ``object_model`` (the shape,
asset or URDF model), ``lasr_sequence``; instance extras ``color``, ``size``, and for
articulated parts ``urdf`` / ``articulated_links`` (base) or ``articulated_link`` /
``articulated_base`` (other links).

Random draws per seed, in order: background hue, lamp jitter, object type, shape or model (both
drawn even when an option fixes them, so the later draws do not shift), colour, orientation,
speed, direction, spin, spin axis, camera distance, elevation, azimuth. Size: the PFM flow and
occlusion files are uncompressed float32, 16 bytes per pixel per flow direction and frame
(``lasr/`` of a default scene: 60 MB; ``lasr_export=false`` leaves it out).
"""

from __future__ import annotations

import math
import pathlib
import tempfile

import numpy as np

import kubric as kb
from kubric.io.scene_dir import LASR_DIR
from kubric.io.scene_writer import write_scene
from kubric.pipeline import Option, OptionError, Recipe, float_range, resolution
from kubric.recipes import vbr_schema
from kubric.recipes.articulated_models import MODELS, add_model
from kubric.recipes.common import (
    annotate_instances,
    check_source_options,
    kubasic_sources,
    open_existing_source,
    scene_documents,
)
from kubric.recipes.complex_brdf import SHAPES
from kubric.recipes.movi import add_clevr_lights
from kubric.recipes.movi_base import new_camera
from kubric.recipes.people import add_person, open_people_sources, source_options
from kubric.recipes.render_quality import RenderQuality

ELEVATION_DEG = (10.0, 50.0)


def unit_vector(rng) -> np.ndarray:
    """A direction uniform on the unit sphere."""
    while True:
        v = rng.normal(size=3)
        n = float(np.linalg.norm(v))
        if n > 1e-9:
            return v / n



def key_free_flight(scene, obj) -> None:
    """Key ``obj``'s pose at frames 0 .. frame_end + 1 as the free flight its velocity and angular
    velocity give without gravity (what the simulator computes for a rigid object): a kinematic
    character moves by keys only. The velocities are then zeroed (the keys carry the motion)."""
    q0 = kb.Quaternion(obj.quaternion)
    p0 = np.asarray(obj.position, np.float64)
    v = np.asarray(obj.velocity, np.float64)
    w = np.asarray(obj.angular_velocity, np.float64)
    speed = float(np.linalg.norm(w))
    for frame in range(0, scene.frame_end + 2):
        t = frame / scene.frame_rate
        turn = kb.Quaternion(axis=w / speed, angle=speed * t) if speed > 0 else kb.Quaternion()
        obj.position = p0 + v * t
        obj.quaternion = turn * q0
        obj.keyframe_insert("position", frame)
        obj.keyframe_insert("quaternion", frame)
    obj.velocity = obj.angular_velocity = (0.0, 0.0, 0.0)


def _base_color(obj) -> tuple:
    """Linear RGB of an object's material colour (grey when it has none)."""
    color = getattr(obj.material, "color", None)
    return tuple(color.rgb) if color is not None and hasattr(color, "rgb") else (0.8, 0.8, 0.8)


def by_visible_pixels(parts) -> list:
    """Every part (hidden ones too: an articulated object keeps all its links), most visible
    pixels first, ties in model order."""
    return sorted(parts, key=lambda p: -int(np.sum(p.metadata["visibility"])))


def lasr_writer(scene_dir: pathlib.Path, sequence: str, root: int):
    """The writer of a scene's ``lasr/`` folder, for ``write_scene``'s ``files``: the LASR
    export (:mod:`kubric.datasets.exports.lasr`) of the layers written before it."""
    def write_lasr(path: pathlib.Path) -> None:
        from kubric.datasets.exports.lasr import export_lasr
        export_lasr(scene_dir, path, sequence=sequence, root=root)
    return write_lasr


class Vbr(RenderQuality, Recipe, name="vbr"):
    """Video-based reconstruction (LASR): a rigid or articulated object moves and spins for 30 frames.

    RGB, silhouette, flow with occlusion and a camera per frame, in our format and as a LASR
    sequence (lasr/)."""

    schema = vbr_schema.VBR

    resolution = Option((256, 256), "(width, height) in pixels: N or WxH", type=resolution)
    num_frames = Option(30, "rendered frames (files 0 .. num_frames-1)", low=2, limit=10000)
    frame_rate = Option(12, "frames per second", low=1, limit=1000)
    step_rate = Option(240, "physics steps per second (a multiple of frame_rate)", low=1,
                       limit=100000)
    object_type = Option("random", "rigid (a KuBasic shape or an objects_source asset), "
                         "articulated (a multi-link URDF), character (a person performing a "
                         "clip), or random per seed (rigid or articulated)",
                         choices=("random", "rigid", "articulated", "character"))
    shape = Option("random", "rigid: the KuBasic shape, or random per seed (ignored with "
                   "objects_source)", choices=("random", *SHAPES))
    objects_source = Option(None, "rigid: mesh asset source to draw the object from (default: "
                            "the KuBasic shapes)", type=pathlib.Path, must_exist=True)
    articulated_model = Option("random", "articulated: the pybullet_data model, or random per "
                               "seed", choices=("random", *MODELS))
    urdf_file = Option(None, "articulated: a multi-link .urdf file to use instead of "
                       "articulated_model", type=pathlib.Path, must_exist=True)
    object_size = Option(1.5, "largest extent of the object (m; articulated: in its rest pose)",
                         low=0.01, limit=100.0)
    speed_range = Option((0.2, 0.6), "object speed (m/s) low,high", type=float_range, low=0.0,
                         limit=100.0)
    spin_range = Option((1.0, 2.5), "angular speed (rad/s) low,high", type=float_range, low=0.0,
                        limit=100.0)
    camera_distance = Option((4.0, 5.0), "camera distance (m) from the origin low,high",
                             type=float_range, low=0.1, limit=1000.0)
    camera = Option("static", "static: looks at the origin; follow: turns every frame to look "
                    "at the object's centre", choices=("static", "follow"))
    kubasic_source = Option(None, "KuBasic asset source folder (default: built locally)",
                            type=pathlib.Path, must_exist=True)
    character_source, motion_source = source_options("character: ")
    lasr_export = Option(True, "also write the LASR sequence into lasr/ "
                         "(kubric.datasets.exports.lasr)")

    # ------------------------------------------------------------------ checks
    def check(self) -> None:
        if self.step_rate % self.frame_rate:
            raise OptionError(f"{self.name}: option step_rate={self.step_rate} must be a multiple "
                              f"of frame_rate={self.frame_rate}")
        check_source_options(self)
        self.check_renderer()
        path = self.urdf_file
        if path is not None:
            from kubric.assets.articulated import link_visuals
            where = f"{self.name}: option urdf_file={str(path)!r}"
            if not (path.is_file() and path.suffix.lower() == ".urdf"):
                raise OptionError(f"{where} is not a .urdf file")
            try:
                visuals = link_visuals(path)
            except (ValueError, OSError) as err:
                raise OptionError(f"{where}: {' '.join(str(err).split())[:200]}") from None
            if not visuals:
                raise OptionError(f"{where}: no link has a <visual> to render")

    def renderer_requests(self) -> dict[str, str]:
        out = super().renderer_requests()
        if self.object_type == "character":
            out["characters"] = "object_type=character"
        return out

    def prepare(self) -> None:
        self.open_sources()

    def open_sources(self) -> dict:
        sources = kubasic_sources(self.kubasic_source)
        if self.objects_source is not None:
            sources["objects"] = open_existing_source(self.objects_source, "objects_source")
        if self.object_type == "character":
            sources.update(open_people_sources(self.character_source, self.motion_source))
        return sources

    # ------------------------------------------------------------------ steps
    def build_background(self, scene, rng) -> str:
        color = kb.random_hue_color(saturation=0.3, value=0.5, rng=rng)
        scene.background = color
        add_clevr_lights(scene, rng)
        return color.hexstr

    def add_object(self, scene, simulator, rng, sources, scratch):
        """Add the object; returns (object type, model name, base, parts, centre offset in the
        base frame)."""
        kind = ("rigid", "articulated")[rng.randint(2)]
        kind = kind if self.object_type == "random" else self.object_type
        if kind == "character":
            person = add_person(scene, sources, rng, (0.0, 0.0), "object")
            rest = np.asarray(person.rest_bounds, np.float64)
            person.scale = self.object_size / max(float(np.max(rest[1] - rest[0])), 1e-9)
            person.position = (0.0, 0.0, 0.0)
            person.metadata = {**person.metadata, "size": float(self.object_size),
                               "color": np.asarray(_base_color(person), np.float32)}
            model = f"{person.metadata['character_id']}/{person.metadata['motion_id']}"
            return kind, model, person, [person], person.scale * rest.mean(axis=0)
        if kind == "articulated":
            model = sorted(MODELS)[rng.randint(len(MODELS))]
            model = model if self.articulated_model == "random" else self.articulated_model
            urdf = None
            if self.urdf_file is not None:
                model, urdf = self.urdf_file.stem, str(self.urdf_file)
            color = kb.random_hue_color(rng=rng)
            base, links, bounds = add_model(scene, simulator, model, self.object_size, color,
                                            pathlib.Path(scratch) / "links", "object", urdf=urdf)
            for part in (base, *links.values()):
                part.metadata = {**part.metadata, "size": float(self.object_size)}
            return kind, model, base, [base, *links.values()], bounds.mean(axis=0)
        if "objects" in sources:
            ids = sources["objects"].all_asset_ids
            model = ids[rng.randint(len(ids))]
            obj = sources["objects"].create(model)
        else:
            model = SHAPES[rng.randint(len(SHAPES))]
            model = model if self.shape == "random" else self.shape
            obj = sources["kubasic"].create(model)
        color = kb.random_hue_color(rng=rng)
        bounds = np.asarray(obj.bounds, np.float64)
        obj.scale = self.object_size / max(float(np.max(bounds[1] - bounds[0])), 1e-9)
        obj.material = kb.PrincipledBSDFMaterial(color=color, roughness=0.5)
        obj.metadata = {**obj.metadata, "color": np.asarray(color.rgb, np.float32),
                        "size": float(self.object_size)}
        scene.add(obj)
        return kind, model, obj, [obj], obj.scale * bounds.mean(axis=0)

    def set_motion(self, scene, base, centre, rng) -> None:
        """Random orientation, velocity and spin; the centre passes the origin half-way."""
        base.quaternion = kb.random_rotation(rng=rng)
        speed = rng.uniform(*self.speed_range)
        velocity = speed * unit_vector(rng)
        spin = rng.uniform(*self.spin_range)
        base.angular_velocity = spin * unit_vector(rng)
        base.velocity = velocity
        t_mid = (scene.frame_start + scene.frame_end) / 2.0 / scene.frame_rate
        offset = kb.Quaternion(base.quaternion).rotate(centre)
        base.position = -np.asarray(offset) - velocity * t_mid
        if isinstance(base, kb.Character):
            key_free_flight(scene, base)

    def place_camera(self, scene, rng):
        distance = rng.uniform(*self.camera_distance)
        elevation = math.radians(rng.uniform(*ELEVATION_DEG))
        azimuth = rng.uniform(0.0, 2.0 * math.pi)
        camera = new_camera()
        camera.position = distance * np.array([math.cos(elevation) * math.cos(azimuth),
                                               math.cos(elevation) * math.sin(azimuth),
                                               math.sin(elevation)])
        camera.look_at((0.0, 0.0, 0.0))
        scene.camera = camera
        return camera

    def follow(self, scene, camera, base, centre) -> None:
        """Key the camera at every simulated frame to look at the object's centre."""
        for frame in range(0, scene.frame_end + 2):
            q = kb.Quaternion(base.get_value_at("quaternion", frame))
            target = np.asarray(base.get_value_at("position", frame)) + q.rotate(centre)
            camera.look_at(target)
            camera.keyframe_insert("quaternion", frame)

    # ------------------------------------------------------------------ the pipeline
    def generate(self, seed: int, out_dir: pathlib.Path) -> None:
        rng = np.random.RandomState(seed)
        sources = self.open_sources()
        scene = kb.Scene(resolution=self.resolution, frame_start=1, frame_end=self.num_frames)
        scene.set_rates(self.frame_rate, self.step_rate)
        scene.gravity = (0.0, 0.0, 0.0)
        sequence = f"{self.name}_{int(seed):08d}"
        with tempfile.TemporaryDirectory(prefix="kubric_vbr_") as scratch:
            simulator = kb.simulator.PyBullet(scene, scratch)
            background = self.build_background(scene, rng)
            kind, model, base, parts, centre = self.add_object(scene, simulator, rng, sources,
                                                               scratch)
            self.set_motion(scene, base, centre, rng)
            camera = self.place_camera(scene, rng)
            _, collisions = simulator.run(frame_start=0, frame_end=scene.frame_end + 1)
            if self.camera == "follow":
                self.follow(scene, camera, base, centre)
            renderer = kb.renderer.create(self.renderer, scene, scratch,
                                          **self.renderer_settings())
            layers = renderer.render()
            settings = self.render_metadata(renderer)
            if kind == "character":  # before the segmentation is relabelled
                from kubric.annotations.keypoints import annotate_keypoints
                annotate_keypoints(scene, layers, [base])
            order = annotate_instances(scene, layers, parts, order=by_visible_pixels)
            metadata, events = scene_documents(
                self, scene, seed, order, collisions, background=background, renderer=settings,
                object_type=kind, object_model=model,
                lasr_sequence=sequence if self.lasr_export else None)
            files = {}
            if self.lasr_export:  # an export of the written layers: the writer calls it
                files[LASR_DIR] = lasr_writer(out_dir, sequence, order.index(base))
            write_scene(self.schema, out_dir, layers, metadata, events, files=files)
            simulator.close()

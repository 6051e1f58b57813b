"""The MOVi recipes A–F (shared steps in :mod:`kubric.recipes.movi_base`; docs/recipes.md).

* A: 3–10 CLEVR shapes (cube, cylinder, sphere), small 0.7 / large 1.4, 8 CLEVR colours, metal or
  rubber; grey dome, 4 jittered lamps, ambient 0.05; camera at (7.48, −6.51, 5.34) + U[0,1)³.
* B: 3–10 of the KuBasic shapes (all but the dome), size U(0.7, 1.4), random hue, metal or rubber;
  dome of random hue; lamps as A; camera in the shell r ∈ [7, 9].
* C: 3–10 objects of a mesh collection, size U(0.75, 3.0) relative to the largest bound, their own
  textures, μ 0.5, e 0.5, mass from the asset; HDRI dome (floor and backdrop) and HDRI light.
  The dome is a FlatMaterial (invisible to non-camera rays) showing the HDRI ground-projected from
  ``HDRI_PROJECTION_HEIGHT`` m above the floor centre; its floor catches the objects' shadows
  (``catch_shadows``; option ``floor_shadows=false`` gives the unlit floor).
* D: 10–20 static + 1–3 dynamic objects; the static ones settle first (μ 1, e 0), then stop.
* E: as D with a camera moving on a straight line (start in the shell [8, 12], length U(0, 4)).
  ``camera=panning``: its look-at point moves on a line too (:func:`panning_look_at_path`).
* F: as E with motion blur U(0, 2) frames and 512² images.
* C–F, ``articulated_objects=N`` (default 0): N multi-link URDF models of ``pybullet_data``
  (``articulated_models``; :mod:`kubric.recipes.articulated_models`) join the dynamic objects,
  sized, placed and thrown as they are; every link is simulated (passive joints) and is an
  instance with its own segmentation label (metadata ``articulated_link`` / ``articulated_base``,
  the base ``urdf`` / ``articulated_links``). At 0 the scene is byte for byte what it was
  without the option (no random draw, no flag). Not in A / B: their schemas label every
  instance with a CLEVR / KuBasic shape.
* C–F, ``characters=N`` (default 0): N people (``character_source``, default the MakeHuman humans
  source; ``procedural`` = the built-in tube person) perform clips from ``motion_source``,
  starting at free spots within ±3 m of the centre; they are added first, so the objects are
  placed around them and fall onto them, bouncing off their kinematic colliders (collisions in
  ``events.json``); one extra dynamic object per person starts 0.3–1 m above where its head is 0.4
  s later, with no horizontal velocity (instance metadata ``dropped_on``: the person's uid). Each
  person is an instance with its keypoints in the metadata (docs/characters.md); tracks follow
  their skinned surfaces. At 0 the scene is byte for byte what it was without the option.
* C–F, ``cloths=N`` / ``soft_objects=N`` (default 0): N checker-textured cloth sheets / soft
  toys (:mod:`kubric.recipes.deformable_objects`) fall from above onto the objects, simulated by
  PyBullet's soft bodies, two-way with them; each is an instance whose tracks follow material
  points of the simulated mesh (docs/deformables.md); ``soft_shapes`` (default ``box``) lists
  the toys' shapes (the box, closed KuBasic shapes). At 0 the scene is byte for byte what it was
  without the options.

Materials (A, B): CLEVR's metal and rubber (BSDF, friction μ, restitution e, density); mass =
the asset's mass (volume × density 1 at scale 1) × density × size³. The CLEVR values (shapes,
colours, sizes, materials, lamps, camera) are defined once, in :mod:`kubric.assets.clevr`, and
listed in docs/assets.md ("CLEVR facts").
"""

from __future__ import annotations

import abc

import numpy as np

import kubric as kb
from kubric import asset_tools
from kubric.assets import clevr
from kubric.assets.utils import get_clevr_lights
from kubric.pipeline import Option, OptionError, float_range
from kubric.recipes import movi_schema
from kubric.recipes.articulated_models import MODELS, add_model, model_list
from kubric.recipes.common import open_existing_source, source_location
from kubric.recipes.deformable_objects import add_deformables, soft_shape_list
from kubric.recipes.exposure_schema import EXPOSURE_VARIANTS
from kubric.recipes.material_options import MaterialOptions
from kubric.recipes.movi_base import (
    CAMERA_MIN_HEIGHT,
    DYNAMIC_SPAWN_REGION,
    MOVING_CAMERA_SHELL,
    STATIC_SPAWN_REGION,
    MoviBase,
    new_camera,
    place_without_overlap,
)
from kubric.recipes.people import add_person, free_spots, open_people_sources, source_options

#: C–F: height (m) above the floor of the viewpoint from which the dome looks up the HDRI (about
#: an HDRI's capture height): the floor shows the HDRI's ground, the backdrop its horizon and sky.
HDRI_PROJECTION_HEIGHT = 2.0
#: C–F, ``characters=N``: people start at spots in [−CHARACTER_REGION, CHARACTER_REGION]² (m)
CHARACTER_REGION = 3.0


def add_clevr_lights(scene, rng, jitter: float = 1.0) -> list:
    """Add the CLEVR lamps (:func:`kubric.assets.utils.get_clevr_lights`) and ambient 0.05."""
    lights = get_clevr_lights(light_jitter=jitter, rng=rng)
    scene.add(lights)
    scene.ambient_illumination = kb.Color(0.05, 0.05, 0.05)
    return lights


def category_list(value) -> tuple[str, ...]:
    """Option converter: ``"Shoe,Toys"`` or a sequence of names → a tuple of category names."""
    items = value.split(",") if isinstance(value, str) else list(value)
    names = tuple(str(v).strip() for v in items if str(v).strip())
    if not names:
        raise ValueError("expected one or more category names separated by commas")
    return names


category_list.allowed = "category names separated by commas, e.g. Shoe,Toys"


def _choice(rng, items):
    items = list(items)
    return items[rng.randint(len(items))]


class _ClevrLike(MoviBase):
    """Shared by A and B: KuBasic shapes, metal or rubber, CLEVR lamps."""

    min_num_objects = Option(3, "fewest objects", low=1, high=100)
    max_num_objects = Option(10, "most objects", low=1, high=100)

    def shape_ids(self, sources) -> list[str]:
        return [i for i in sources["kubasic"].all_asset_ids if i != "dome"]

    @abc.abstractmethod
    def sample_look(self, rng):
        """(size label, size, color label, Color) of a new object."""

    def add_objects(self, scene, simulator, rng, sources):
        shapes = self.shape_ids(sources)
        for _ in range(rng.randint(self.min_num_objects, self.max_num_objects + 1)):
            shape = _choice(rng, shapes)
            size_label, size, color_label, color = self.sample_look(rng)
            material_name = _choice(rng, sorted(clevr.MATERIALS))
            params, friction, restitution, density = clevr.MATERIALS[material_name]
            obj = sources["kubasic"].create(shape, scale=size, friction=friction,
                                            restitution=restitution)
            obj.mass = obj.mass * density * size ** 3
            obj.material = kb.PrincipledBSDFMaterial(color=color, **params)
            obj.metadata = {**obj.metadata, "shape": shape, "size": float(size),
                            "size_label": size_label, "material": material_name,
                            "color": np.asarray(color.rgb, dtype=np.float32),
                            "color_label": color_label, "is_dynamic": True}
            scene.add(obj)
            if place_without_overlap(obj, simulator, DYNAMIC_SPAWN_REGION, rng):
                self.initial_velocity(obj, rng)


class MoviA(_ClevrLike, name="movi_a"):
    """MOVi-A: 3–10 CLEVR shapes (metal / rubber, 8 colours, 2 sizes), grey dome, CLEVR lamps."""

    schema = movi_schema.MOVI_A
    variants = (movi_schema.MOVI_TRACKS["movi_a"], *EXPOSURE_VARIANTS["movi_a"])

    def shape_ids(self, sources):
        missing = [s for s in clevr.SHAPES if s not in sources["kubasic"]]
        if missing:
            raise OptionError(f"{self.name}: the KuBasic source lacks {missing}")
        return list(clevr.SHAPES)

    def sample_look(self, rng):
        size_label = _choice(rng, sorted(clevr.SIZES))
        color_label = _choice(rng, sorted(clevr.COLORS))
        return size_label, clevr.SIZES[size_label], color_label, clevr.COLORS[color_label]

    def build_background(self, scene, rng, sources):
        floor = kb.get_color("gray")
        self.add_dome(scene, sources, kb.PrincipledBSDFMaterial(color=floor, roughness=1.0,
                                                                specular=0.0))
        add_clevr_lights(scene, rng)
        return floor.hexstr

    def build_camera(self, scene, rng):
        camera = new_camera()
        camera.position = np.asarray(clevr.CAMERA_POSITION) + rng.rand(3)
        camera.look_at((0.0, 0.0, 0.0))
        scene.camera = camera


class MoviB(_ClevrLike, name="movi_b"):
    """MOVi-B: 3–10 KuBasic shapes, size U(0.7, 1.4), random hue, dome of random hue."""

    schema = movi_schema.MOVI_B
    variants = (movi_schema.MOVI_TRACKS["movi_b"], *EXPOSURE_VARIANTS["movi_b"])

    size_range = Option((clevr.SIZES["small"], clevr.SIZES["large"]), "object scale range low,high",
                        type=float_range, low=0.01, limit=100.0)

    def sample_look(self, rng):
        size = float(rng.uniform(*self.size_range))
        color = kb.random_hue_color(rng=rng)
        return "", size, color.hexstr, color

    def build_background(self, scene, rng, sources):
        floor = kb.random_hue_color(saturation=0.5, value=0.7, rng=rng)
        self.add_dome(scene, sources, kb.PrincipledBSDFMaterial(color=floor, roughness=1.0,
                                                                specular=0.0))
        add_clevr_lights(scene, rng)
        return floor.hexstr


class MoviC(MaterialOptions, MoviBase, name="movi_c"):
    """MOVi-C: 3–10 scanned-like objects with their own textures on an HDRI dome, HDRI light."""

    schema = movi_schema.MOVI_C
    variants = (movi_schema.MOVI_TRACKS["movi_c"], *EXPOSURE_VARIANTS["movi_c"])

    min_num_objects = Option(3, "fewest objects", low=1, high=100)
    max_num_objects = Option(10, "most objects", low=1, high=100)
    size_range = Option((0.75, 3.0), "largest extent range (m) low,high", type=float_range,
                        low=0.01, limit=100.0)
    objects_source = Option(None, "mesh asset source folder (default: the converted "
                            "pybullet_data collection)", type=source_location)
    hdri_source = Option(None, "HDRI asset source folder (default: the HDRIs shipped with bpy)",
                         type=source_location)
    collection_limit = Option(None, "with the default objects_source: convert only this many of "
                              "pybullet_data's random_urdfs (none = all 1000)", type=int, low=0)
    split = Option("train", "asset / background split (10% of the sorted ids are held out)",
                   choices=("train", "test"))
    object_categories = Option(None, "only objects of these categories (comma-separated, as "
                               "in the source's metadata, e.g. Shoe,Toys; none = all); the 10% "
                               "split is made over the whole source first", type=category_list)
    floor_shadows = Option(True, "the HDRI floor receives the objects' shadows "
                           "(FlatMaterial.catch_shadows); false = unlit floor, faster")
    articulated_objects = Option(0, "multi-link URDF models (pybullet_data) added as dynamic "
                                 "objects, every link an instance (0 = none: the scene is as "
                                 "without this option)", low=0, high=20)
    articulated_models = Option(tuple(MODELS), "the models the articulated objects are drawn "
                                "from (comma-separated)", type=model_list)
    characters = Option(0, "people performing motion clips among the objects, which fall and "
                        "bounce off them (0 = none: the scene is as without this option)",
                        low=0, high=10)
    character_source, motion_source = source_options("with characters: ")
    cloths = Option(0, "cloth sheets that fall onto the objects (PyBullet soft bodies; 0 = none: "
                    "the scene is as without this option)", low=0, high=5)
    soft_objects = Option(0, "soft toys (squishy boxes, PyBullet NeoHookean bodies) that fall "
                          "onto the objects (0 = none: the scene is as without this option)",
                          low=0, high=5)
    soft_shapes = Option(("box",), "the soft toys' shapes, drawn per toy: the procedural box "
                         "and closed KuBasic shapes tetrahedralised (comma-separated)",
                         type=soft_shape_list)

    #: left out of ``flags`` while ``articulated_objects`` is 0, so that a scene made without
    #: articulated objects is byte for byte the scene made before these options existed
    ARTICULATED_OPTIONS = ("articulated_objects", "articulated_models")
    #: likewise while ``characters`` is 0
    CHARACTER_OPTIONS = ("characters", "character_source", "motion_source")

    def check(self) -> None:
        super().check()
        self.open_materials()

    def flags(self, seed: int) -> dict:
        out = self.material_flags(super().flags(seed))
        if not self.articulated_objects:
            for name in self.ARTICULATED_OPTIONS:
                out.pop(name)
        if not self.characters:
            for name in self.CHARACTER_OPTIONS:
                out.pop(name)
        for name in ("cloths", "soft_objects"):
            if not getattr(self, name):
                out.pop(name)
        if not self.soft_objects or tuple(self.soft_shapes) == ("box",):
            out.pop("soft_shapes")
        return out

    def renderer_requests(self) -> dict[str, str]:
        out = super().renderer_requests()
        if self.characters:
            out["characters"] = f"characters={self.characters}"
        return {**out, **self.material_requests()}

    def finish_scene(self, scene, seed: int) -> None:
        """Random PBR materials (``material_source``) for the objects and the dome."""
        dome = next((a for a in scene.assets if a.name == "dome"), None)
        self.apply_materials(scene, seed, dome)

    def open_sources(self):
        sources = super().open_sources()
        sources["objects"] = open_existing_source(self.objects_source, "objects_source") \
            if self.objects_source is not None else \
            asset_tools.ensure_pybullet_collection(limit=self.collection_limit)
        sources["hdri"] = open_existing_source(self.hdri_source, "hdri_source") \
            if self.hdri_source is not None else asset_tools.ensure_hdri_source()
        for key in ("objects", "hdri"):
            categories = self.object_categories if key == "objects" else None
            try:
                ids = sources[key].asset_ids(categories, split=self.split, fraction=0.1)
            except KeyError as err:
                raise OptionError(f"{self.name}: option object_categories: {err.args[0]}") \
                    from None
            if not ids:
                raise OptionError(f"{self.name}: the {key} source has no {self.split} assets")
            sources[key + "_ids"] = ids
        if self.characters:
            sources.update(open_people_sources(self.character_source, self.motion_source))
        return sources

    def build_background(self, scene, rng, sources):
        hdri_id = _choice(rng, sources["hdri_ids"])
        hdri = sources["hdri"].create(hdri_id, mapping="environment")
        # The dome shows the HDRI ground-projected (its texel values exactly where nothing
        # shadows it, so it matches the world background); with floor_shadows its floor is a
        # shadow catcher (albedo normalised by the HDRI's irradiance), so objects cast contact
        # shadows on it. It is invisible to every other ray, so the objects are lit by (and
        # reflect) the HDRI itself and the dome's wall does not block it.
        scene.background = hdri
        scene.ambient_illumination = hdri
        ground = sources["hdri"].create(hdri_id, mapping="environment",
                                        projection_height=HDRI_PROJECTION_HEIGHT)
        self.add_dome(scene, sources, kb.FlatMaterial(color=ground, indirect_visibility=False,
                                                      catch_shadows=self.floor_shadows))
        return hdri_id

    def new_object(self, scene, simulator, rng, sources, region, dynamic: bool):
        """A new object of the source, sized, placed without overlap with its bounding box in
        ``region`` (or in ``region(obj)`` when that is a function of the sized object)."""
        asset_id = _choice(rng, sources["objects_ids"])
        obj = sources["objects"].create(asset_id, friction=0.5, restitution=0.5)
        size = float(rng.uniform(*self.size_range))
        extent = float(np.max(obj.bounds[1] - obj.bounds[0]))
        obj.scale = size / extent
        obj.metadata = {**obj.metadata, "scale": size, "is_dynamic": dynamic}
        scene.add(obj)
        if callable(region):
            region = region(obj)
        if not place_without_overlap(obj, simulator, region, rng):
            return None
        if dynamic:
            self.initial_velocity(obj, rng)
        return obj

    def add_objects(self, scene, simulator, rng, sources):
        people = self.add_characters(scene, rng, sources)
        self.drop_on_people(scene, simulator, rng, sources, people)
        for _ in range(rng.randint(self.min_num_objects, self.max_num_objects + 1)):
            self.new_object(scene, simulator, rng, sources, DYNAMIC_SPAWN_REGION, True)
        self.add_articulated_objects(scene, simulator, rng)
        self.drop_deformables(scene, simulator, rng, sources)

    def add_characters(self, scene, rng, sources) -> list:
        """``characters`` people (no random draw when 0), added before the objects so that the
        objects are placed around them (their colliders count as overlaps) and fall onto them:
        spots in [−CHARACTER_REGION, CHARACTER_REGION]² at least 1 m apart
        (:func:`kubric.recipes.people.add_person`); a person with no free spot is counted in
        ``dropped_objects``. Returns the people."""
        if not self.characters:
            return []
        spots = free_spots(rng, self.characters, CHARACTER_REGION, 1.0)
        scene.metadata["dropped_objects"] += self.characters - len(spots)
        return [add_person(scene, sources, rng, spot, f"person_{k}")
                for k, spot in enumerate(spots)]

    def drop_on_people(self, scene, simulator, rng, sources, people) -> None:
        """One extra dynamic object per person, placed without overlap above where the person
        is 0.4 s into the clip (its centre within about ±0.3 m of the person's box centre at that
        frame in x and y, its bottom 0.3–1 m above the person's top; the region is widened by
        the object's bounding radius) and dropped with no horizontal velocity, so that it falls
        onto the moving body."""
        def above(x, y, top):
            def region(obj):  # room for the object's box in any orientation around the centre
                b = np.asarray(obj.bounds, np.float64) * np.asarray(obj.scale, np.float64)
                r = 0.5 * float(np.linalg.norm(b[1] - b[0]))
                return ((x - 0.3 - r, y - 0.3 - r, top + 0.3), (x + 0.3 + r, y + 0.3 + r,
                                                                 top + 1.0 + 2 * r))
            return region

        aim = int(round(0.4 * scene.frame_rate))  # about when it reaches the person
        for person in people:
            box = person.aabb(aim)
            x, y = box.mean(axis=0)[:2]
            obj = self.new_object(scene, simulator, rng, sources, above(x, y, float(box[1, 2])),
                                  True)
            if obj is not None:
                obj.velocity = (0.0, 0.0, 0.0)
                obj.metadata = {**obj.metadata, "dropped_on": person.uid}

    def write_outputs(self, scene, layers, collisions, seed, out_dir, background,
                      render_settings, files=None) -> list:
        for obj in scene.foreground_assets:  # instances/category (upstream's GSO names)
            if isinstance(obj, kb.PhysicalObject):
                obj.metadata = {**obj.metadata, movi_schema.MOVI_CATEGORY:
                                movi_schema.movi_category(obj.metadata)}
        if self.characters:
            from kubric.annotations.keypoints import annotate_keypoints
            annotate_keypoints(scene, layers)
        return super().write_outputs(scene, layers, collisions, seed, out_dir, background,
                                     render_settings, files)

    def drop_deformables(self, scene, simulator, rng, sources) -> None:
        """``cloths`` sheets and ``soft_objects`` toys above everything (no random draw when
        both are 0; module doc)."""
        if self.cloths or self.soft_objects:
            add_deformables(scene, rng, self.cloths, self.soft_objects,
                            simulator.scratch_dir / "deformables", self.soft_shapes,
                            sources["kubasic"])

    def add_articulated_objects(self, scene, simulator, rng) -> None:
        """``articulated_objects`` dynamic multi-link models (no random draw when 0): model,
        largest rest-pose extent U(``size_range``), colour; placed and thrown as the others.
        Each part's metadata: ``scale`` (that extent), ``is_dynamic``, ``color`` and the link
        names (:mod:`kubric.recipes.articulated_models`)."""
        for k in range(self.articulated_objects):
            model = _choice(rng, self.articulated_models)
            size = float(rng.uniform(*self.size_range))
            name = f"articulated_{k}"
            base, links, _ = add_model(scene, simulator, model, size, kb.random_hue_color(rng=rng),
                                       simulator.scratch_dir / name, name, friction=0.5,
                                       restitution=0.5)
            for part in (base, *links.values()):
                part.metadata = {**part.metadata, "scale": size, "is_dynamic": True}
            if place_without_overlap(base, simulator, DYNAMIC_SPAWN_REGION, rng):
                self.initial_velocity(base, rng)
            else:  # the base was removed (and counted): its links go with it
                for link in links.values():
                    scene.remove(link)


class MoviD(MoviC, name="movi_d"):
    """MOVi-D: 10–20 static objects that settle first, then 1–3 dynamic ones thrown in."""

    schema = movi_schema.MOVI_D
    variants = (movi_schema.MOVI_TRACKS["movi_d"], *EXPOSURE_VARIANTS["movi_d"])

    min_num_objects = Option(10, "fewest static objects", low=0, high=100)
    max_num_objects = Option(20, "most static objects", low=0, high=100)
    min_num_dynamic = Option(1, "fewest dynamic objects", low=1, high=20)
    max_num_dynamic = Option(3, "most dynamic objects", low=1, high=20)
    settle_frames = Option(100, "frames the static objects settle for", low=0, limit=10000)

    def add_objects(self, scene, simulator, rng, sources):
        people = self.add_characters(scene, rng, sources)
        static = []
        for _ in range(rng.randint(self.min_num_objects, self.max_num_objects + 1)):
            obj = self.new_object(scene, simulator, rng, sources, STATIC_SPAWN_REGION, False)
            if obj is not None:
                obj.friction, obj.restitution = 1.0, 0.0
                static.append(obj)
        if static and self.settle_frames:
            simulator.run(frame_start=-self.settle_frames, frame_end=0)
        for obj in static:
            obj.velocity = (0.0, 0.0, 0.0)
            obj.angular_velocity = (0.0, 0.0, 0.0)
            obj.friction, obj.restitution = 0.5, 0.5
        self.drop_on_people(scene, simulator, rng, sources, people)
        for _ in range(rng.randint(self.min_num_dynamic, self.max_num_dynamic + 1)):
            self.new_object(scene, simulator, rng, sources, DYNAMIC_SPAWN_REGION, True)
        self.add_articulated_objects(scene, simulator, rng)
        self.drop_deformables(scene, simulator, rng, sources)


def linear_camera_path(rng, inner: float, outer: float, max_length: float):
    """(start, end): start uniform in the half-sphere shell, end = start + a random direction ×
    U(0, max_length), resampled until the end also lies in the shell above CAMERA_MIN_HEIGHT."""
    length = float(rng.uniform(0.0, max_length))
    while True:
        start = kb.sample_point_in_half_sphere_shell(inner, outer, CAMERA_MIN_HEIGHT, rng=rng)
        direction = rng.rand(3) - 0.5
        norm = np.linalg.norm(direction)
        if norm < 1e-9:
            continue
        end = start + direction / norm * length
        if inner <= np.linalg.norm(end) <= outer and end[2] > CAMERA_MIN_HEIGHT:
            return start, end


def panning_look_at_path(rng, inner: float = 1.0, outer: float = 4.0):
    """(start, end) of a moving look-at point (TAP-Vid's panning MOVi-E, upstream's
    ``linear_movement_linear_lookat``): the path passes through a point ``through`` in the
    half-sphere of radius ``inner``; one end is in the half-sphere of radius ``outer`` below
    height ``inner``, the other continues past ``through`` by U(0, 0.5) of that distance; the
    direction is reversed with probability 1/2."""
    through = kb.sample_point_in_half_sphere_shell(0.0, inner, 0.0, rng=rng)
    while True:
        start = kb.sample_point_in_half_sphere_shell(0.0, outer, 0.0, rng=rng)
        if start[2] < inner:
            break
    end = through + float(rng.uniform(0.0, 0.5)) * (through - start)
    return (end, start) if rng.rand() < 0.5 else (start, end)


class MoviE(MoviD, name="movi_e"):
    """MOVi-E: as D with the camera moving on a straight line, looking at the origin (or, with
    camera=panning, at a point that moves on a line too)."""

    schema = movi_schema.MOVI_E
    variants = (movi_schema.MOVI_TRACKS["movi_e"], *EXPOSURE_VARIANTS["movi_e"])

    max_camera_movement = Option(4.0, "largest camera path length (m)", low=0.0, limit=100.0)
    camera = Option("linear", "linear: look at the origin; panning: the look-at point moves on "
                    "a line through the centre region too", choices=("linear", "panning"))

    def build_camera(self, scene, rng):
        camera = new_camera()
        scene.camera = camera
        start, end = linear_camera_path(rng, *MOVING_CAMERA_SHELL, self.max_camera_movement)
        look_start = look_end = np.zeros(3)
        if self.camera == "panning":
            look_start, look_end = panning_look_at_path(rng)
        scene.metadata["camera_look_at"] = {"start": np.asarray(look_start, float).tolist(),
                                            "end": np.asarray(look_end, float).tolist()}
        first, last = scene.frame_start - 1, scene.frame_end + 1
        for frame in range(min(first, 0), last + 1):
            t = (frame - first) / (last - first)
            camera.position = (1.0 - t) * start + t * end
            camera.look_at((1.0 - t) * look_start + t * look_end)
            camera.keyframe_insert("position", frame)
            camera.keyframe_insert("quaternion", frame)


class MoviF(MoviE, name="movi_f"):
    """MOVi-F: as E with motion blur U(0, max_motion_blur) frames, 512² by default."""

    schema = movi_schema.MOVI_F
    variants = (movi_schema.MOVI_TRACKS["movi_f"], *EXPOSURE_VARIANTS["movi_f"])

    resolution = Option((512, 512), MoviBase.resolution.help, type=MoviBase.resolution.type)
    max_motion_blur = Option(2.0, "largest shutter length (frames)", low=0.0, high=10.0)

    def motion_blur(self, rng):
        return float(rng.uniform(0.0, self.max_motion_blur))

    def populate(self, scene, simulator, rng, sources):
        """As E's, and the shutter length is recorded as ``metadata.motion_blur`` (frames;
        upstream MOVi-F's ``metadata/motion_blur``), besides ``metadata.renderer``."""
        background, blur = super().populate(scene, simulator, rng, sources)
        scene.metadata["motion_blur"] = blur
        return background, blur

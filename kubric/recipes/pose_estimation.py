"""``pose_estimation``: people performing motion clips in a randomized room (the paper's pose
estimation challenge), with the 17 COCO keypoints per person per frame (docs/characters.md).

Scene (every random number from the seed, in this order):

1. **Room**: a floor, a ceiling and four walls (a square room of half-width U(4, 5.5) m, walls
   3 m high),
   each with its own random material (random hue, saturation ≤ 0.4, roughness U(0.3, 1));
   1–2 rectangular area lights under the ceiling pointing down plus ambient light 0.1. Clutter:
   ``min_num_clutter``–``max_num_clutter`` KuBasic shapes (size U(0.2, 0.6) m, random hue),
   standing on the floor at random places near the walls; floor, walls and clutter are the
   background (segmentation label 0, no instances: the instances are the people).
2. **People**: ``min_num_people``–``max_num_people`` characters drawn from ``character_source``,
   each performing a clip drawn from ``motion_source`` from a random start time (so that the
   scene's duration fits in the clip when it can; the clip holds its last pose after its end),
   with a random heading, starting (the clip's root offset at its start cancelled) at a spot in
   the room's centre (x, y ∈ [−1.2, 1.2] m, at least 0.8 m apart).
3. **Camera** at human height: U(3, 4.5) m from the people's mean start position at a random
   azimuth (moved inside the walls, 0.3 m from them, when it would be outside), height
   U(1.4, 1.8) m, looking at that position 1 m above the floor; MOVi's 35 mm lens.
4. The people's colliders join a physics run (nothing else moves), then the render.

Outputs: the MOVi files (RGB, the exact layers, ``metadata.json``, ``events.json``; boxes per
frame in ``instances[k].bboxes``) and, per person instance, the keypoint fields of
:mod:`kubric.annotations.keypoints` (``keypoints_2d``, ``keypoints_3d``, ``keypoints_camera``,
``keypoints_visibility``, ...). The track options work as in MOVi (tracks follow the skinned
surfaces). Sources: the default is the MakeHuman humans source and its retargeted CMU / DeepMimic
clips (``kubric assets humans``, built on first use); ``procedural`` picks the built-in tube
person and its walk (``kubric.assets.procedural_character``), which needs no download.
"""

from __future__ import annotations

import numpy as np

import kubric as kb
from kubric.annotations.keypoints import annotate_keypoints
from kubric.pipeline import Option, OptionError
from kubric.recipes.movi_base import MoviBase, new_camera
from kubric.recipes.people import (
    add_person,
    asset_ids,
    free_spots,
    open_people_sources,
    source_options,
)
from kubric.recipes.pose_estimation_schema import SCHEMA, TRACKS_SCHEMA

WALL_HEIGHT, ROOM_HALF_RANGE, PEOPLE_REGION, MIN_PERSON_GAP = 3.0, (4.0, 5.5), 1.2, 0.8
CAMERA_DISTANCE, CAMERA_HEIGHT = (3.0, 4.5), (1.4, 1.8)

class PoseEstimation(MoviBase, name="pose_estimation"):
    """Pose estimation: 1–3 people performing motion clips in a random room, COCO keypoints."""

    schema = SCHEMA
    variants = (TRACKS_SCHEMA,)

    min_num_people = Option(1, "fewest people", low=1, high=10)
    max_num_people = Option(3, "most people", low=1, high=10)
    min_num_clutter = Option(2, "fewest clutter objects (KuBasic shapes) along the walls",
                             low=0, high=50)
    max_num_clutter = Option(6, "most clutter objects", low=0, high=50)
    character_source, motion_source = source_options("")

    renderer_needs = ("characters",)

    def open_sources(self) -> dict:
        sources = super().open_sources()
        sources.update(open_people_sources(self.character_source, self.motion_source))
        for key in ("characters", "motions"):
            if not asset_ids(sources[key]):
                raise OptionError(f"{self.name}: the {key} source holds no assets")
        return sources

    # ------------------------------------------------------------------ the room
    def build_background(self, scene, rng, sources) -> str:
        half = float(rng.uniform(*ROOM_HALF_RANGE))
        t = 0.05
        parts = {"floor": ((0, 0, -t), (half, half, t)),
                 "ceiling": ((0, 0, WALL_HEIGHT + t), (half, half, t))}
        for name, pos, size in (("wall_north", (0, half + t, WALL_HEIGHT / 2), (half, t, 0)),
                                ("wall_south", (0, -half - t, WALL_HEIGHT / 2), (half, t, 0)),
                                ("wall_east", (half + t, 0, WALL_HEIGHT / 2), (t, half, 0)),
                                ("wall_west", (-half - t, 0, WALL_HEIGHT / 2), (t, half, 0))):
            parts[name] = (pos, (size[0], size[1], WALL_HEIGHT / 2))
        for name, (pos, size) in parts.items():
            color = kb.random_hue_color(saturation=float(rng.uniform(0, 0.4)),
                                        value=float(rng.uniform(0.4, 0.9)), rng=rng)
            scene += kb.Cube(name=name, position=pos, scale=size, static=True, background=True,
                             friction=0.5, material=kb.PrincipledBSDFMaterial(
                                 color=color, roughness=float(rng.uniform(0.3, 1.0))))
        for i in range(rng.randint(1, 3)):
            x, y = rng.uniform(-half / 2, half / 2, 2)
            scene += kb.RectAreaLight(name=f"ceiling_light_{i}", position=(x, y, WALL_HEIGHT - 0.1),
                                      look_at=(x, y, 0), width=1.0, height=1.0,
                                      intensity=float(rng.uniform(60, 120)))
        scene.ambient_illumination = kb.Color(0.1, 0.1, 0.1)
        scene.metadata["room_half_width"] = half
        return "room"

    # ------------------------------------------------------------------ people and clutter
    def add_objects(self, scene, simulator, rng, sources) -> None:
        half = scene.metadata["room_half_width"]
        shapes = [i for i in sources["kubasic"].all_asset_ids if i != "dome"]
        for _ in range(rng.randint(self.min_num_clutter, self.max_num_clutter + 1)):
            size = float(rng.uniform(0.2, 0.6))
            obj = sources["kubasic"].create(shapes[rng.randint(len(shapes))], static=True,
                                            background=True)
            b = np.asarray(obj.bounds, np.float64)
            obj.scale = size / max(float(np.max(b[1] - b[0])), 1e-9)
            side, along = rng.randint(4), float(rng.uniform(-half + 0.5, half - 0.5))
            inset = half - 0.4
            x, y = [(along, inset), (along, -inset), (inset, along), (-inset, along)][side]
            obj.position = (x, y, -float(b[0, 2]) * float(obj.scale[2]))
            obj.quaternion = kb.Quaternion(axis=(0, 0, 1), angle=float(rng.uniform(0, 2 * np.pi)))
            obj.material = kb.PrincipledBSDFMaterial(color=kb.random_hue_color(rng=rng),
                                                     roughness=0.6)
            scene += obj
        wanted = rng.randint(self.min_num_people, self.max_num_people + 1)
        spots = free_spots(rng, wanted, PEOPLE_REGION, MIN_PERSON_GAP)
        scene.metadata["dropped_objects"] += wanted - len(spots)
        for k, spot in enumerate(spots):
            person = add_person(scene, sources, rng, spot, f"person_{k}")
            if person.keypoint_regressor is None:  # refused before rendering, not after
                raise OptionError(f"{self.name}: character {person.metadata['character_id']!r} "
                                  "of character_source has no keypoint regressor, and this "
                                  "recipe annotates COCO keypoints; give a source whose "
                                  "characters have one (the humans source, or procedural)")

    def populate(self, scene, simulator, rng, sources):
        """Room, then clutter and people, then the camera (which aims at the people)."""
        background = self.build_background(scene, rng, sources)
        self.add_objects(scene, simulator, rng, sources)
        self.build_camera(scene, rng)
        return background, 0.0

    def build_camera(self, scene, rng) -> None:
        """Camera at human height looking at the people (module doc)."""
        camera = new_camera()
        half = scene.metadata["room_half_width"] - 0.3
        people = [a for a in scene.assets if isinstance(a, kb.Character)]
        centre = np.mean([np.asarray(p.position)[:2] for p in people], axis=0) if people \
            else np.zeros(2)
        azimuth = float(rng.uniform(0, 2 * np.pi))
        dist = float(rng.uniform(*CAMERA_DISTANCE))
        xy = np.clip(centre + dist * np.array([np.cos(azimuth), np.sin(azimuth)]), -half, half)
        camera.position = (float(xy[0]), float(xy[1]), float(rng.uniform(*CAMERA_HEIGHT)))
        camera.look_at((float(centre[0]), float(centre[1]), 1.0))
        scene.camera = camera

    def write_outputs(self, scene, layers, collisions, seed, out_dir, background,
                      render_settings, files=None) -> list:
        annotate_keypoints(scene, layers)
        scene.metadata.pop("room_half_width", None)
        return super().write_outputs(scene, layers, collisions, seed, out_dir, background,
                                     render_settings, files)

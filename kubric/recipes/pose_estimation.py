"""``pose_estimation``: people performing motion clips in a randomized room (the paper's pose
estimation challenge), with the 17 COCO keypoints per person per frame (docs/characters.md).

Scene (every random number from the seed, in this order):

1. **Room**: a floor, a ceiling and four walls (a square room of half-width U(3, 4.5) m, walls 3 m high),
   each with its own random material (random hue, saturation ≤ 0.4, roughness U(0.3, 1));
   1–2 rectangular area lights under the ceiling pointing down plus ambient light 0.1. Clutter:
   ``min_num_clutter``–``max_num_clutter`` KuBasic shapes (size U(0.2, 0.6) m, random hue),
   standing on the floor at random places near the walls; floor, walls and clutter are the
   background (segmentation label 0, no instances: the instances are the people).
2. **People**: ``min_num_people``–``max_num_people`` characters drawn from ``character_source``,
   each performing a clip drawn from ``motion_source`` from a random start time (so that the
   scene's duration fits in the clip when it can; the clip holds its last pose after its end),
   with a random heading, starting (the clip's root offset at its start cancelled) at a spot in
   the room's centre (x, y ∈ [−1.5, 1.5] m, at least 0.8 m apart).
3. **Camera** at human height: U(2.5, half-width − 0.3) m from the room's centre at a random
   azimuth, height U(1.4, 1.8) m, looking at the room's centre 1 m above the floor (the people
   stand within 1.5 m of it); MOVi's 35 mm lens.
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
from kubric.pipeline import Option, OptionError
from kubric.recipes.common import open_existing_source, source_location
from kubric.recipes.movi_base import MoviBase, new_camera
from kubric.recipes.pose_estimation_schema import SCHEMA

PROCEDURAL = "procedural"
WALL_HEIGHT, ROOM_HALF_RANGE, PEOPLE_REGION, MIN_PERSON_GAP = 3.0, (3.0, 4.5), 1.5, 0.8

def character_location(value):
    """Option converter: ``procedural`` or an asset source (see :func:`source_location`)."""
    if isinstance(value, str) and value.strip().lower() == PROCEDURAL:
        return PROCEDURAL
    return source_location(value)


character_location.allowed = f"{PROCEDURAL!r}, or " + source_location.allowed
character_location.__name__ = "procedural|path|URL"


class ProceduralSource:
    """The built-in tube person / walk clip as a one-asset source (``asset_ids``, ``create``)."""

    def __init__(self, kind: str):
        self.kind = kind

    def asset_ids(self) -> list[str]:
        return ["tube_person"] if self.kind == "characters" else ["procedural_walk"]

    def create(self, asset_id: str, **kwargs):
        from kubric.assets.procedural_character import tube_person, walk_clip
        if self.kind == "characters":
            kwargs.setdefault("material", kb.PrincipledBSDFMaterial(
                color=kb.Color(0.55, 0.38, 0.28), roughness=0.6))
            return tube_person(**kwargs)
        return walk_clip(seconds=4.0)


def open_people_sources(character_source, motion_source) -> dict:
    """``{"characters": source, "motions": source}`` for the two options (module doc)."""
    out = {}
    humans = None
    for key, value in (("characters", character_source), ("motions", motion_source)):
        if value == PROCEDURAL:
            out[key] = ProceduralSource(key)
        elif value is not None:
            out[key] = open_existing_source(value, f"{key[:-1]}_source")
        else:
            if humans is None:
                from kubric import assets
                if not hasattr(assets, "ensure_humans"):
                    raise OptionError("the default humans source needs kubric.assets."
                                      "ensure_humans (`kubric assets humans`), which this "
                                      "installation lacks; give character_source=procedural "
                                      "motion_source=procedural or source folders")
                humans = assets.ensure_humans()
            out[key] = humans[0] if key == "characters" else humans[1]
    return out


def _ids(source) -> list[str]:
    ids = source.asset_ids() if callable(getattr(source, "asset_ids", None)) else \
        list(source.all_asset_ids)
    return sorted(ids)


class PoseEstimation(MoviBase, name="pose_estimation"):
    """Pose estimation: 1–3 people performing motion clips in a random room, COCO keypoints."""

    schema = SCHEMA

    min_num_people = Option(1, "fewest people", low=1, high=10)
    max_num_people = Option(3, "most people", low=1, high=10)
    min_num_clutter = Option(2, "fewest clutter objects (KuBasic shapes) along the walls",
                             low=0, high=50)
    max_num_clutter = Option(6, "most clutter objects", low=0, high=50)
    character_source = Option(None, "character asset source (folder or URL), or 'procedural' "
                              "(the built-in tube person); default: the MakeHuman humans source",
                              type=character_location)
    motion_source = Option(None, "motion-clip asset source (folder or URL), or 'procedural' "
                           "(the built-in walk); default: the humans source's clips",
                           type=character_location)

    def open_sources(self) -> dict:
        sources = super().open_sources()
        sources.update(open_people_sources(self.character_source, self.motion_source))
        for key in ("characters", "motions"):
            if not _ids(sources[key]):
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
        character_ids, motion_ids = _ids(sources["characters"]), _ids(sources["motions"])
        spots: list[np.ndarray] = []
        for k in range(rng.randint(self.min_num_people, self.max_num_people + 1)):
            spot = None
            for _ in range(100):
                cand = rng.uniform(-PEOPLE_REGION, PEOPLE_REGION, 2)
                if all(np.linalg.norm(cand - s) >= MIN_PERSON_GAP for s in spots):
                    spot = cand
                    break
            if spot is None:
                scene.metadata["dropped_objects"] += 1
                continue
            spots.append(spot)
            cid = character_ids[rng.randint(len(character_ids))]
            mid = motion_ids[rng.randint(len(motion_ids))]
            person = sources["characters"].create(cid, name=f"person_{k}")
            heading = kb.Quaternion(axis=(0, 0, 1), angle=float(rng.uniform(0, 2 * np.pi)))
            clip = sources["motions"].create(mid)
            seconds = (scene.frame_end + 1) / scene.frame_rate
            start = float(rng.uniform(0, max(clip.duration - seconds, 0.0)))
            # the clip's root offset at its start is cancelled, so the person starts at the spot
            offset = clip.sample([start])[1][0] * np.asarray(person.scale, np.float64)
            shift = heading.rotate(offset)
            person.position = (float(spot[0] - shift[0]), float(spot[1] - shift[1]), 0.0)
            person.quaternion = heading
            scene += person
            person.play(clip, start_frame=0, end_frame=scene.frame_end + 1,
                        frame_rate=scene.frame_rate, clip_start=start)
            person.metadata = {**person.metadata, "character_id": cid, "motion_id": mid,
                               "motion_start": start}
        scene.metadata["people_spots"] = [s.tolist() for s in spots]

    def build_camera(self, scene, rng) -> None:
        """Camera at human height inside the room (module doc)."""
        camera = new_camera()
        azimuth = float(rng.uniform(0, 2 * np.pi))
        dist = float(rng.uniform(2.5, scene.metadata["room_half_width"] - 0.3))
        camera.position = (dist * np.cos(azimuth), dist * np.sin(azimuth),
                           float(rng.uniform(1.4, 1.8)))
        camera.look_at((0.0, 0.0, 1.0))
        scene.camera = camera

    def write_outputs(self, scene, layers, collisions, seed, out_dir, background,
                      render_settings) -> list:
        from kubric.annotations.keypoints import annotate_keypoints
        annotate_keypoints(scene, layers)
        scene.metadata.pop("room_half_width", None)
        scene.metadata.pop("people_spots", None)
        return super().write_outputs(scene, layers, collisions, seed, out_dir, background,
                                     render_settings)

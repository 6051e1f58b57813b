"""Robust NeRF: ``robust_nerf`` (the paper's "Robust NeRF" teleport / jitter challenges).

A static scene of ``min_num_objects``–``max_num_objects`` upright KuBasic shapes (random hue) on a
grey floor with CLEVR lamps, seen by an **orbit** camera (``num_views`` evenly spaced views at
elevation ``orbit_elevation`` and distance ``orbit_distance``, starting at a random azimuth), plus
``num_impostors`` impostor objects (KuBasic ``impostor_shape``, default ``suzanne``, the paper's
monkey head) that break the static-scene assumption, **in train views only**:

* ``impostor_motion=teleport``: in every train view each impostor stands at a new random place
  of the floor square ±``region`` (random turn about z);
* ``impostor_motion=jitter``: each impostor keeps one random place, displaced in every train view by
  U(−``jitter``, ``jitter``) in x and y.

Impostors never overlap the static objects or each other (their footprint circles, grown by the
jitter, are kept apart). In val and test views they are parked out of sight,
``PARKED_POSITION`` below the floor. Per view it writes ``impostor_mask_{i:05d}.png`` (1 where an
impostor is visible); instances get ``is_impostor`` and ``present`` (per view: whether the object
is in the scene).
"""

from __future__ import annotations

import math

from kubric.pipeline import Option, OptionError, float_range
from kubric.recipes import multiview_schema
from kubric.recipes.multiview_base import (
    ExtraOutputs,
    MultiviewBase,
    flag_mask,
    footprint_radius,
    free_place,
    kubasic_object,
    orbit_positions,
    stand_upright,
)

PARKED_POSITION = (0.0, 0.0, -1000.0)


class RobustNerf(MultiviewBase, name="robust_nerf"):
    """Robust NeRF: static KuBasic scene + impostors that teleport or jitter in train views."""

    schema = multiview_schema.ROBUST_NERF

    num_views = Option(32, "number of views on the orbit (the paper: ~300)", low=1, high=10000)
    min_num_objects = Option(4, "fewest static objects", low=1, high=100)
    max_num_objects = Option(8, "most static objects", low=1, high=100)
    size_range = Option((0.8, 1.4), "static object scale range low,high (shapes fit a 1 m cube)",
                        type=float_range, low=0.05, limit=100.0)
    region = Option(3.5, "objects and impostors stand in the square ±region (m)", low=0.5)
    num_impostors = Option(1, "number of impostor objects", low=0, high=20)
    impostor_shape = Option("suzanne", "KuBasic shape of the impostors")
    impostor_size = Option(1.0, "impostor scale", low=0.05)
    impostor_motion = Option("teleport", "how impostors move between train views",
                             choices=("teleport", "jitter"))
    jitter = Option(0.3, "jitter: largest displacement (m) in x and y from the fixed place",
                    low=0.0)
    orbit_distance = Option(8.0, "orbit radius (m)", low=0.1)
    orbit_elevation = Option(30.0, "orbit elevation above the horizon (degrees)", low=-89.0,
                             high=89.9)

    def build_background(self, scene, rng, sources):
        return self.grey_background(scene, rng, sources)

    def add_objects(self, scene, rng, sources):
        shapes = [s for s in sources["kubasic"].all_asset_ids if s != "dome"]
        self.occupied = []
        for _ in range(rng.randint(self.min_num_objects, self.max_num_objects + 1)):
            shape = shapes[rng.randint(len(shapes))]
            obj = kubasic_object(sources, shape, float(rng.uniform(*self.size_range)), rng)
            obj.metadata = {**obj.metadata, "shape": shape, "is_impostor": False,
                            "present": [True] * self.num_views}
            self.add_upright(scene, obj, rng, self.occupied, self.region)

    def camera_positions(self, rng):
        phase = rng.uniform(0.0, 2.0 * math.pi)
        return orbit_positions(self.num_views, self.orbit_distance, self.orbit_elevation,
                               self.look_at(), phase)

    def animate(self, scene, rng, splits, sources):
        if self.impostor_shape not in sources["kubasic"]:
            raise OptionError(f"{self.name}: option impostor_shape={self.impostor_shape!r} is not "
                              f"a KuBasic shape")
        impostors = []
        for _ in range(self.num_impostors):
            obj = kubasic_object(sources, self.impostor_shape, self.impostor_size, rng)
            obj.metadata = {**obj.metadata, "shape": self.impostor_shape, "is_impostor": True,
                            "present": [s == "train" for s in splits]}
            scene.add(obj)
            impostors.append(obj)
        slack = self.jitter * math.sqrt(2.0) if self.impostor_motion == "jitter" else 0.0
        homes = []
        if self.impostor_motion == "jitter":
            taken = list(self.occupied)
            for obj in impostors:
                homes.append(self._free_place(obj, rng, taken, slack))
        for frame, split in zip(scene.frames, splits, strict=True):
            taken = list(self.occupied)
            for k, obj in enumerate(impostors):
                if split != "train":
                    obj.position = PARKED_POSITION
                elif self.impostor_motion == "teleport":
                    stand_upright(obj, *self._free_place(obj, rng, taken, 0.0))
                else:
                    xy, yaw = homes[k]
                    stand_upright(obj, xy + rng.uniform(-self.jitter, self.jitter, 2), yaw)
                obj.keyframe_insert("position", frame)
                obj.keyframe_insert("quaternion", frame)

    def _free_place(self, obj, rng, taken: list, slack: float):
        place = free_place(rng, taken, footprint_radius(obj) + slack, self.region)
        if place is None:
            raise RuntimeError(f"{self.name}: no free place for an impostor in ±{self.region} m; "
                               "lower max_num_objects or raise region")
        return place

    def extra_outputs(self, scene, layers, instances, meta):
        return ExtraOutputs(layers={"impostor_mask": flag_mask(layers, instances, "is_impostor")})

"""``svr``: single-view reconstruction / visual pre-training data (the paper renders every
ShapeNet object in random poses on transparent backgrounds).

Scene ``k`` shows asset ``k`` of the source's sorted ids (after ``object_categories`` and
``split``; ``k`` wraps around), so seeds ``0 .. n−1`` cover every asset once. The object (largest
extent ``object_size``) stands at the origin in a uniformly random orientation; ``num_views``
cameras (default 24) look at it from random directions on the whole sphere at
``camera_distance``; CLEVR lamps plus ambient light; the film is transparent (alpha 0 wherever no
object is). The object's pose and category are in the instance metadata (``quaternions``,
``category``, ``asset_id``) and each view's camera in ``metadata.json["camera"]`` and the
NeRF ``transforms_*.json``.

Random draws per seed, in order: lamp jitter (CLEVR lamps), object orientation, camera positions.
"""

from __future__ import annotations

import pathlib

from kubric.pipeline import Option, OptionError, float_range
from kubric.recipes import multiview_schema
from kubric.recipes.common import source_location
from kubric.recipes.movi import add_clevr_lights, category_list
from kubric.recipes.multiview_base import MultiviewBase, open_source, sphere_cap_positions


class Svr(MultiviewBase, name="svr"):
    """Single-view reconstruction / pre-training: asset k (seed k) in 24 random views on a
    transparent background, pose and category in the metadata."""

    schema = multiview_schema.SVR

    num_views = Option(24, "number of random views of the object", low=1, high=10000)
    objects_source = Option(None, "mesh asset source (default: the KuBasic shapes)",
                            type=source_location)
    object_categories = Option(None, "only assets of these categories (comma-separated; none "
                               "= all)", type=category_list)
    split = Option("all", "asset split: all, or train / test (10% of the sorted ids held out, "
                   "seed 42)", choices=("all", "train", "test"))
    object_size = Option(1.0, "largest extent of the object (m)", low=0.01)
    camera_distance = Option((2.5, 2.5), "camera distance (m) from the object, low,high",
                             type=float_range, low=0.1)

    def check(self) -> None:
        super().check()
        if not self.object_size < self.camera_distance[0]:  # the camera inside the object
            raise OptionError(f"{self.name}: object_size={self.object_size:g} m must be smaller "
                              f"than the nearest camera distance {self.camera_distance[0]:g} m "
                              "(camera_distance), or the views see no object")

    def open_sources(self) -> dict:
        sources = super().open_sources()
        if self.objects_source is not None:
            sources["objects"] = open_source(self.objects_source, "objects_source")
        else:
            sources["objects"] = sources["kubasic"]
        source = sources["objects"]
        try:
            ids = source.asset_ids(self.object_categories,
                                   split=None if self.split == "all" else self.split)
        except KeyError as err:
            raise OptionError(f"{self.name}: option object_categories: {err.args[0]}") from None
        if source is sources["kubasic"]:
            ids = [i for i in ids if i != "dome"]
        if not ids:
            raise OptionError(f"{self.name}: the objects source has no {self.split} assets")
        sources["object_ids"] = ids
        return sources

    def renderer_options(self) -> dict:
        return {"background_transparency": True}

    def build_background(self, scene, rng, sources) -> str:
        import kubric as kb

        add_clevr_lights(scene, rng)
        scene.ambient_illumination = kb.Color(0.3, 0.3, 0.3)
        return "transparent"

    def add_objects(self, scene, rng, sources) -> None:
        import numpy as np

        import kubric as kb

        ids = sources["object_ids"]
        asset_id = ids[self.seed % len(ids)]
        obj = sources["objects"].create(asset_id)
        bounds = np.asarray(obj.bounds, np.float64)
        obj.scale = self.object_size / max(float(np.max(bounds[1] - bounds[0])), 1e-9)
        obj.quaternion = kb.random_rotation(rng=rng)
        centre = obj.scale * (bounds[0] + bounds[1]) / 2.0
        obj.position = -np.asarray(kb.Quaternion(obj.quaternion).rotate(centre))
        obj.metadata = {**obj.metadata, "asset_index": int(self.seed % len(ids)),
                        "size": float(self.object_size)}
        scene.add(obj)

    def camera_positions(self, rng):
        return sphere_cap_positions(rng, self.num_views, self.camera_distance, (-89.9, 89.9),
                                    self.look_at())

    def generate(self, seed: int, out_dir: pathlib.Path) -> None:
        self.seed = int(seed)
        super().generate(seed, out_dir)

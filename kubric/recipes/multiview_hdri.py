"""Object-centric multi-view recipes on HDRI backgrounds: ``multiview_matting`` and ``nvs``.

Both put upright objects of ``objects`` (an asset source; default: the KuBasic shapes, the dome
left out — pass a mesh collection such as a converted ShapeNet for the paper's setting) on the
HDRI dome of a random HDRI of ``hdri_source`` (lit by the same HDRI, as MOVi-C), each object
scaled so that its largest extent is drawn from its size range, and render ``num_views`` random
views on a sphere cap.

* ``multiview_matting`` (the paper's multi-view salient object detection): one salient object at
  the centre of the floor; ``difficulty=hard`` adds ``min_num_clutter``–``max_num_clutter`` smaller
  clutter objects around it. Per view ``mask_{i:05d}.png``: 1 where the salient object is visible.
  Instances get ``is_salient``.
* ``nvs`` (conditional novel view synthesis): a group of ``min_num_objects``–``max_num_objects``
  objects near the centre, 10 views at 128² by default.
"""

from __future__ import annotations

import numpy as np

import kubric as kb
from kubric.pipeline import Option, OptionError, float_range
from kubric.recipes import multiview_schema
from kubric.recipes.common import open_existing_source as open_source
from kubric.recipes.common import source_location
from kubric.recipes.multiview_base import (
    ExtraOutputs,
    MultiviewBase,
    flag_mask,
    footprint_radius,
    open_hdri_source,
    sized_object,
    stand_upright,
)


class _HdriObjects(MultiviewBase):
    """Shared by multiview_matting and nvs."""

    num_views = Option(10, "number of camera views", low=1, high=10000)
    objects = Option(None, "asset source folder of the objects (default: the KuBasic shapes)",
                     type=source_location)
    hdri_source = Option(None, "HDRI asset source folder (default: the HDRIs shipped with bpy)",
                         type=source_location)

    def open_sources(self):
        sources = super().open_sources()
        sources["objects"] = sources["kubasic"] if self.objects is None else \
            open_source(self.objects, "objects")
        sources["object_ids"] = [i for i in sources["objects"].all_asset_ids if i != "dome"]
        sources["hdri"] = open_hdri_source(self.hdri_source)
        return sources

    def build_background(self, scene, rng, sources):
        return self.hdri_background(scene, rng, sources)

    def random_object(self, rng, sources, size_range):
        """A random asset, its largest extent U(size_range); KuBasic shapes (no textures of
        their own) get a random-hue material."""
        ids = sources["object_ids"]
        obj = sized_object(sources["objects"], ids[rng.randint(len(ids))],
                           float(rng.uniform(*size_range)))
        if self.objects is None:
            color = kb.random_hue_color(rng=rng)
            obj.material = kb.PrincipledBSDFMaterial(color=color, roughness=0.5)
            obj.metadata = {**obj.metadata, "color": np.asarray(color.rgb, np.float32)}
        return obj


class MultiviewMatting(_HdriObjects, name="multiview_matting"):
    """Multi-view object matting: one salient object (easy) or plus clutter (hard), HDRI."""

    schema = multiview_schema.MULTIVIEW_MATTING

    resolution = Option((256, 256), MultiviewBase.resolution.help,
                        type=MultiviewBase.resolution.type)
    difficulty = Option("easy", "easy: the salient object alone; hard: plus clutter",
                        choices=("easy", "hard"))
    salient_size = Option((1.5, 2.0), "largest extent (m) of the salient object low,high",
                          type=float_range, low=0.05)
    min_num_clutter = Option(3, "hard: fewest clutter objects", low=0, high=50)
    max_num_clutter = Option(6, "hard: most clutter objects", low=0, high=50)
    clutter_size = Option((0.5, 1.0), "largest extent (m) of a clutter object low,high",
                          type=float_range, low=0.05)
    region = Option(2.5, "clutter stands in the square ±region (m)", low=0.5)
    camera_distance = Option((3.5, 5.0), MultiviewBase.camera_distance.help,
                             type=float_range, low=0.1)
    elevation_range = Option((10.0, 50.0), MultiviewBase.elevation_range.help,
                             type=float_range, low=-89.0, high=89.9)

    def look_at(self):
        return (0.0, 0.0, 0.6)

    def add_objects(self, scene, rng, sources):
        salient = self.random_object(rng, sources, self.salient_size)
        salient.metadata = {**salient.metadata, "is_salient": True}
        stand_upright(salient, (0.0, 0.0), rng.uniform(0.0, 2.0 * np.pi))
        scene.add(salient)
        occupied = [(np.zeros(2), footprint_radius(salient))]
        if self.difficulty == "easy":
            return
        for _ in range(rng.randint(self.min_num_clutter, self.max_num_clutter + 1)):
            obj = self.random_object(rng, sources, self.clutter_size)
            obj.metadata = {**obj.metadata, "is_salient": False}
            self.add_upright(scene, obj, rng, occupied, self.region)

    def extra_outputs(self, scene, layers, instances, meta):
        return ExtraOutputs(layers={"mask": flag_mask(layers, instances, "is_salient")})


class Nvs(_HdriObjects, name="nvs"):
    """Conditional novel view synthesis: a group of objects on an HDRI, 10 views at 128²."""

    schema = multiview_schema.NVS

    min_num_objects = Option(3, "fewest objects", low=1, high=50)
    max_num_objects = Option(6, "most objects", low=1, high=50)
    size_range = Option((0.6, 1.2), "largest object extent (m) low,high", type=float_range,
                        low=0.05, limit=100.0)
    region = Option(2.2, "objects stand in the square ±region (m)", low=0.3)
    camera_distance = Option((5.0, 7.0), MultiviewBase.camera_distance.help,
                             type=float_range, low=0.1)

    def add_objects(self, scene, rng, sources):
        occupied = []
        placed = 0
        for _ in range(rng.randint(self.min_num_objects, self.max_num_objects + 1)):
            obj = self.random_object(rng, sources, self.size_range)
            placed += self.add_upright(scene, obj, rng, occupied, self.region)
        if placed < self.min_num_objects:  # an impossible request, refused before rendering
            raise OptionError(f"{self.name}: only {placed} objects of sizes {self.size_range} m "
                              f"fit in the square ±{self.region} m, fewer than "
                              f"min_num_objects={self.min_num_objects}; lower min_num_objects "
                              "or size_range, or raise region")

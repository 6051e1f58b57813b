"""Scene semantic segmentation: ``klevr`` and ``toybox`` (the paper's KLEVR / ToyBox5 / ToyBox13).

* ``klevr``: 4–12 upright KuBasic shapes (classes: ``shapes``, default cube, cylinder, sphere,
  cone, torus) of random hue on a neutral-grey dome, CLEVR lamps; views on a sphere cap.
* ``toybox``: the same layout with the objects of an asset source that has categories
  (``--set objects=DIR``, or ``objects_source=DIR`` as MOVi-C–F name it; assets need
  ``metadata.category``): the ``num_categories`` most common categories (5 = ToyBox5, 13 =
  ToyBox13) or the named ``categories``; each object's largest extent is U(``size_range``); an
  HDRI background (as MOVi-C's).

Both write, per view, ``semantic_{i:05d}.png`` (class ids: 0 = background, i.e. floor and
backdrop, k = ``metadata.semantic_classes[k]``; each instance's class is its ``semantic_id``) and,
per scene, ``points.npz``: the labelled point cloud from unprojecting every pixel that hits a
surface with the depth layer (``xyz`` (N,3) float32 world metres, ``rgb`` (N,3) uint8, ``class``
(N,) uint16 semantic id, ``instance`` (N,) uint16 segmentation label, ``view`` (N,) uint16,
``pixel`` (N,2) uint16 (row, col)).
"""

from __future__ import annotations

import abc
import json
import math
import pathlib

import numpy as np

from kubric.assets import clevr
from kubric.core import camera_geometry as geo
from kubric.io.paths import atomic_write_bytes
from kubric.pipeline import Option, OptionError, float_range
from kubric.recipes import multiview_schema
from kubric.recipes.common import open_existing_source as open_source
from kubric.recipes.common import source_location
from kubric.recipes.material_options import MaterialOptions
from kubric.recipes.multiview_base import (
    ExtraOutputs,
    MultiviewBase,
    kubasic_object,
    open_hdri_source,
    sized_object,
)

KLEVR_SHAPES = "cube,cylinder,sphere,cone,torus"


def with_categories(source, categories: dict, out) -> pathlib.Path:
    """Write into ``out`` an asset source that is ``source`` (an AssetSource whose archives sit
    beside its manifest, as KuBasic's) with ``metadata.category = categories[asset_id]`` (none for
    ids not in the dict) and without the dome: e.g. a categorised KuBasic for ``toybox``. The
    archives are linked, not copied. Returns ``out``."""
    root = source.manifest_path.parent
    manifest = json.loads((root / "manifest.json").read_text())
    manifest["assets"].pop("dome", None)
    for asset_id, entry in manifest["assets"].items():
        entry["metadata"].pop("category", None)
        if asset_id in categories:
            entry["metadata"]["category"] = categories[asset_id]
    out = pathlib.Path(out)
    out.mkdir(parents=True, exist_ok=True)
    for archive in root.glob("*.tar.gz"):
        if not (out / archive.name).exists():
            (out / archive.name).symlink_to(archive)
    atomic_write_bytes(json.dumps(manifest, indent=1).encode(), out / "manifest.json")
    return out


def semantic_layer(segmentation, instances) -> np.ndarray:
    """Per-pixel class ids from instance labels and each instance's ``semantic_id``."""
    lut = np.zeros(len(instances) + 1, np.uint32)
    for k, info in enumerate(instances, start=1):
        lut[k] = int(info["semantic_id"])
    return lut[np.asarray(segmentation)]


def point_cloud(camera, frames, layers, semantic) -> dict[str, np.ndarray]:
    """The labelled point cloud of every view (see module doc): pixel-centre rays walked by the
    depth layer; pixels whose ray hits nothing are left out."""
    t, h, w = layers["depth"].shape[:3]
    rows, cols = np.meshgrid(np.arange(h), np.arange(w), indexing="ij")
    pixels_xy = np.stack([cols + 0.5, rows + 0.5], axis=-1)
    parts = {k: [] for k in ("xyz", "rgb", "class", "instance", "view", "pixel")}
    for view, frame in enumerate(frames):
        depth = layers["depth"][view, ..., 0]
        hit = depth < geo.BACKGROUND_DEPTH
        xyz = geo.unproject_pixels(camera, pixels_xy[hit], depth[hit], frame, (w, h))
        parts["xyz"].append(xyz.astype(np.float32))
        parts["rgb"].append(layers["rgba"][view][hit][:, :3])
        parts["class"].append(semantic[view, ..., 0][hit].astype(np.uint16))
        parts["instance"].append(layers["segmentation"][view, ..., 0][hit].astype(np.uint16))
        parts["view"].append(np.full(int(hit.sum()), view, np.uint16))
        parts["pixel"].append(np.stack([rows[hit], cols[hit]], axis=-1).astype(np.uint16))
    return {k: np.concatenate(v) for k, v in parts.items()}


#: the smallest footprint radius of a KuBasic shape per metre of scale: each spans 1 m along x
#: or y (the built manifest's bounds), so half its bounding box's diagonal is ≥ 0.5
MIN_FOOTPRINT = 0.5


def max_objects_on_floor(region: float, radius: float, margin: float = 0.05) -> int:
    """An upper bound on how many footprints of radius ≥ ``radius`` :func:`free_place` can put in
    the square ±``region``: their centres lie in the square (side s = 2·region) at pairwise
    distances ≥ d = 2·radius + margin, and Groemer's inequality bounds such a point set in a
    convex region of area A and perimeter P by 2A / (√3 d²) + P / (2d) + 1."""
    s = 2.0 * region
    d = 2.0 * radius + margin
    bound = 2.0 * s * s / (math.sqrt(3.0) * d * d) + 4.0 * s / (2.0 * d) + 1.0
    return int(bound) if bound < 1e9 else 10**9  # (a huge region: no limit worth stating)


class _SemanticScenes(MultiviewBase):
    """Shared by klevr and toybox."""

    min_num_objects = Option(4, "fewest objects", low=1, high=100)
    max_num_objects = Option(12, "most objects", low=1, high=100)
    region = Option(3.5, "objects stand in the square ±region (m) of the floor", low=0.5)
    write_points = Option(True, "write points.npz (the labelled point cloud of all views)")

    @abc.abstractmethod
    def class_names(self, sources) -> list[str]:
        """Semantic classes without the background (index k-1 = class id k)."""

    @abc.abstractmethod
    def new_object(self, rng, sources, category: str):
        """A new object of ``category`` (one of :meth:`class_names`), not yet placed."""

    def add_objects(self, scene, rng, sources):
        names = self.class_names(sources)
        scene.metadata["semantic_classes"] = ["background"] + names
        occupied = []
        for _ in range(rng.randint(self.min_num_objects, self.max_num_objects + 1)):
            category = names[rng.randint(len(names))]
            obj = self.new_object(rng, sources, category)
            obj.metadata = {**obj.metadata, "category": category,
                            "semantic_id": names.index(category) + 1}
            self.add_upright(scene, obj, rng, occupied, self.region)

    def extra_outputs(self, scene, layers, instances, meta):
        semantic = semantic_layer(layers["segmentation"], instances)
        extra = ExtraOutputs(layers={"semantic": semantic})
        if self.write_points:
            cloud = point_cloud(scene.camera, list(scene.frames), layers, semantic)
            extra.files[multiview_schema.POINTS_FILE] = cloud
            meta["num_points"] = int(len(cloud["xyz"]))
        return extra


class Klevr(_SemanticScenes, name="klevr"):
    """KLEVR: 4–12 upright KuBasic shapes on a grey floor, many views, semantic labels, points."""

    schema = multiview_schema.KLEVR
    variants = (multiview_schema.POINT_SCHEMAS["klevr"],)

    shapes = Option(KLEVR_SHAPES, "comma-separated KuBasic shapes = the semantic classes")
    size_range = Option((0.8, 1.4), "object scale range low,high (shapes fit a 1 m cube)",
                        type=float_range, low=0.05, limit=100.0)

    def check(self):
        super().check()
        if not [s for s in self.shapes.split(",") if s.strip()]:
            raise OptionError(f"{self.name}: option shapes={self.shapes!r} names no shape")
        fits = max_objects_on_floor(self.region, MIN_FOOTPRINT * self.size_range[0])
        if self.min_num_objects > fits:
            raise OptionError(
                f"{self.name}: min_num_objects={self.min_num_objects} objects of scale ≥ "
                f"{self.size_range[0]:g} cannot stand apart in region=±{self.region:g} m (at "
                f"most {fits} fit); enlarge region, lower min_num_objects or size_range")
        if self.kubasic_source is None:  # the built KuBasic: its shapes are known up front
            self.check_shapes(set(clevr.KUBASIC_SHAPES))

    def check_shapes(self, available) -> list[str]:
        names = [s.strip() for s in self.shapes.split(",") if s.strip()]
        available = set(available) - {"dome"}
        missing = [n for n in names if n not in available]
        if missing:
            raise OptionError(f"{self.name}: option shapes names {missing}, not KuBasic shapes; "
                              f"allowed: {sorted(available)}")
        return names

    def class_names(self, sources):
        return self.check_shapes(sources["kubasic"].all_asset_ids)

    def build_background(self, scene, rng, sources):
        return self.grey_background(scene, rng, sources)

    def new_object(self, rng, sources, category):
        return kubasic_object(sources, category, float(rng.uniform(*self.size_range)), rng)


class ToyBox(MaterialOptions, _SemanticScenes, name="toybox"):
    """ToyBox: 4–12 upright objects of an asset source with categories, HDRI background."""

    schema = multiview_schema.TOYBOX
    variants = (multiview_schema.POINT_SCHEMAS["toybox"],)

    objects = Option(None, "asset source folder whose assets have metadata.category (required)",
                     type=source_location)
    objects_source = Option(None, "the same as objects (the name MOVi-C–F use); give one of "
                            "the two; scenes record it as objects", type=source_location)
    num_categories = Option(5, "use the N most common categories (5 = ToyBox5, 13 = ToyBox13)",
                            low=1, high=1000)
    categories = Option("", "comma-separated categories to use instead (empty: the most common)")
    size_range = Option((0.8, 1.6), "largest object extent (m) low,high", type=float_range,
                        low=0.05, limit=100.0)
    hdri_source = Option(None, "HDRI asset source folder (default: the HDRIs shipped with bpy)",
                         type=source_location)

    def flags(self, seed: int) -> dict:
        out = self.material_flags(super().flags(seed))
        out.pop("objects_source", None)  # the alias, recorded as objects (check)
        return out

    def renderer_requests(self) -> dict[str, str]:
        return {**super().renderer_requests(), **self.material_requests()}

    def finish_scene(self, scene, seed: int) -> None:
        """Random PBR materials (``material_source``) for the objects and the dome."""
        dome = next((a for a in scene.assets if a.name == "dome"), None)
        self.apply_materials(scene, seed, dome)

    def check(self):
        if self.objects is not None and self.objects_source is not None:
            raise OptionError(f"{self.name}: give objects or objects_source, not both (objects="
                              f"{str(self.objects)!r}, objects_source="
                              f"{str(self.objects_source)!r})")
        if self.objects_source is not None:  # the alias: recorded as objects
            self.values["objects"], self.values["objects_source"] = self.objects_source, None
        super().check()
        self.open_materials()
        if self.objects is None:
            raise OptionError(f"{self.name}: option objects (or objects_source) is required: an "
                              "asset source folder whose assets have metadata.category")
        self.chosen_categories(open_source(self.objects, "objects"))

    def chosen_categories(self, source) -> list[str]:
        available = source.categories
        if not available:
            raise OptionError(f"{self.name}: option objects={str(self.objects)!r} is a source "
                              "without categories (no asset has metadata.category)")
        named = [c.strip() for c in self.categories.split(",") if c.strip()]
        if named:
            missing = [c for c in named if c not in available]
            if missing:
                raise OptionError(f"{self.name}: option categories names {missing}, not in the "
                                  f"source; allowed: {available}")
            return named
        counts = {c: len(source.asset_ids_in(c)) for c in available}
        ranked = sorted(available, key=lambda c: (-counts[c], c))
        return ranked[:self.num_categories]

    def open_sources(self):
        sources = super().open_sources()
        sources["objects"] = open_source(self.objects, "objects")
        sources["hdri"] = open_hdri_source(self.hdri_source)
        return sources

    def class_names(self, sources):
        return self.chosen_categories(sources["objects"])

    def build_background(self, scene, rng, sources):
        return self.hdri_background(scene, rng, sources)

    def new_object(self, rng, sources, category):
        ids = sources["objects"].asset_ids_in(category)
        asset_id = ids[rng.randint(len(ids))]
        return sized_object(sources["objects"], asset_id, float(rng.uniform(*self.size_range)))

"""Which label of a recipe becomes the COCO category (and BOP does not need one).

One :class:`CategoryScheme` is chosen for an export from its first scene (:func:`scheme_for`);
every scene must agree with it. Per recipe:

=========================================  ====================================================
recipe                                     categories
=========================================  ====================================================
``movi_a``                                 CLEVR shape (``cube``, ``cylinder``, ``sphere``)
``movi_b`` and any scene whose instances   KuBasic shape (the 11 ids of
carry ``shape``                            :data:`kubric.assets.clevr.KUBASIC_SHAPES`)
``klevr``, ``toybox`` (``semantic_classes``  the scene's semantic classes, id = ``semantic_id``
in the metadata)
``movi_c`` – ``movi_f``, ``svr``, other    the asset ``category`` from the objects source's
recipes with an objects source             manifest (all its categories, sorted; id = position
                                           + 1), so every shard numbers them alike
anything else                              one class, ``object``
=========================================  ====================================================

People (scenes with characters: instances carrying ``keypoints_2d``, docs/characters.md) are the
``person`` category, with COCO's ``keypoints`` names and ``skeleton`` in it, after the recipe's
own categories (alone when every instance is a person, as in ``pose_estimation``): a
:class:`PersonScheme` wraps the recipe's scheme and adds to each person's annotation its
``keypoints`` [x1, y1, v1, ...] and ``num_keypoints`` in that frame
(:func:`kubric.annotations.keypoints.coco_keypoints`: COCO's pixel-index coordinates, ours − 0.5;
v 0 outside the image, 1 occluded, 2 visible).

Extending: a scheme's :meth:`CategoryScheme.annotation_extras` returns fields added to each
annotation.
"""

from __future__ import annotations

import numpy as np

from kubric.annotations.keypoints import coco_keypoints
from kubric.assets.clevr import KUBASIC_SHAPES, SHAPES
from kubric.datasets.exports.scenes import ExportError, Scene


class CategoryScheme:
    """``kind``: what the categories are; ``names``: category names, id = position + 1."""

    def __init__(self, kind: str, names, supercategory: str):
        self.kind = kind
        self.names = list(names)
        self.supercategory = supercategory
        self._ids = {n: i + 1 for i, n in enumerate(self.names)}

    @property
    def categories(self) -> list[dict]:
        return [{"id": i + 1, "name": n, "supercategory": self.supercategory}
                for i, n in enumerate(self.names)]

    def label_of(self, instance: dict) -> str:
        if self.kind == "object":
            return "object"
        key = {"shape": "shape", "asset category": "category"}.get(self.kind)
        if self.kind == "semantic":
            return self.names[int(instance["semantic_id"]) - 1]
        return instance.get(key) if key else None

    def category_id(self, scene: Scene, index: int) -> int:
        instance = scene.metadata["instances"][index]
        try:
            name = self.label_of(instance)
        except (KeyError, IndexError, ValueError, TypeError):
            name = None
        if name not in self._ids:
            raise ExportError(f"{scene.path.name}: instance {index} ({instance.get('asset_id')}) "
                              f"has no {self.kind} among the export's categories {self.names}")
        return self._ids[name]

    def check(self, scene: Scene) -> None:
        """One line when ``scene`` does not share this scheme (another recipe, other classes)."""
        if self.kind == "semantic":
            classes = list(scene.metadata["metadata"].get("semantic_classes", []))[1:]
            if classes != self.names:
                raise ExportError(f"{scene.path.name}: semantic classes {classes} differ from "
                                  f"the first scene's {self.names}; export them separately")

    def annotation_extras(self, scene: Scene, index: int, frame: int) -> dict:
        """Fields added to the annotation of instance ``index`` in ``frame`` (none yet)."""
        return {}


def _is_person(instance: dict) -> bool:
    return "keypoints_2d" in instance


class PersonScheme(CategoryScheme):
    """``base``'s categories plus ``person`` (module doc); ``base`` None: people only."""

    def __init__(self, base: CategoryScheme | None, keypoint_names, skeleton):
        names = (base.names if base else []) + ["person"]
        super().__init__((base.kind + " + person") if base else "person", names,
                         base.supercategory if base else "person")
        self.base = base
        self.keypoint_names = list(keypoint_names)
        self.skeleton = [list(p) for p in skeleton]

    @property
    def categories(self) -> list[dict]:
        cats = self.base.categories if self.base else []
        return cats + [{"id": len(cats) + 1, "name": "person", "supercategory": "person",
                        "keypoints": self.keypoint_names, "skeleton": self.skeleton}]

    def category_id(self, scene: Scene, index: int) -> int:
        instance = scene.metadata["instances"][index]
        if _is_person(instance):
            if list(instance.get("keypoint_names", [])) != self.keypoint_names:
                raise ExportError(f"{scene.path.name}: instance {index} has keypoints "
                                  f"{instance.get('keypoint_names')}, the export's person "
                                  f"category {self.keypoint_names}")
            return len(self.names)
        if self.base is None:
            raise ExportError(f"{scene.path.name}: instance {index} "
                              f"({instance.get('asset_id')}) is not a person, and the export's "
                              "only category is person")
        return self.base.category_id(scene, index)

    def check(self, scene: Scene) -> None:
        if self.base is not None:
            self.base.check(scene)
        for index, instance in enumerate(scene.metadata.get("instances", [])):
            if _is_person(instance):
                check_keypoints(scene, index, instance, len(self.keypoint_names))

    def annotation_extras(self, scene: Scene, index: int, frame: int) -> dict:
        instance = scene.metadata["instances"][index]
        if not _is_person(instance):
            return self.base.annotation_extras(scene, index, frame) if self.base else {}
        flat, count = coco_keypoints(instance["keypoints_2d"][frame],
                                     instance["keypoints_visibility"][frame])
        return {"keypoints": flat, "num_keypoints": count}


def check_keypoints(scene: Scene, index: int, instance: dict, count: int) -> None:
    """ExportError (one line) unless the person ``instance`` holds ``keypoints_2d`` as
    (T, K, 2) finite numbers and ``keypoints_visibility`` as (T, K) flags in {0, 1, 2}, T the
    scene's frames and K = ``count`` (the person category's keypoints)."""
    where = f"{scene.path.name}: instance {index}"
    shapes = {"keypoints_2d": (scene.num_frames, count, 2),
              "keypoints_visibility": (scene.num_frames, count)}
    arrays = {}
    for key, shape in shapes.items():
        try:
            arrays[key] = np.asarray(instance.get(key), dtype=np.float64)
        except (TypeError, ValueError):
            raise ExportError(f"{where}: {key} is not an array of numbers (a ragged or "
                              "non-numeric list)") from None
        if arrays[key].shape != shape:
            raise ExportError(f"{where}: {key} has shape {arrays[key].shape}, expected {shape} "
                              "(frames, keypoints[, x y])")
    vis = arrays["keypoints_visibility"]
    if not np.isin(vis, (0, 1, 2)).all():
        raise ExportError(f"{where}: keypoints_visibility holds "
                          f"{vis[~np.isin(vis, (0, 1, 2))][0]!r}; allowed 0, 1, 2")
    shown = arrays["keypoints_2d"][vis > 0]
    if not np.isfinite(shown).all():
        raise ExportError(f"{where}: keypoints_2d holds NaN/inf at a keypoint marked visible")


def scheme_for(scene: Scene, sources=None) -> CategoryScheme:
    """The scheme of ``scene``'s recipe (module doc), with the ``person`` category when the scene
    has people; ``sources``: asset-source paths given on the command line, searched for
    categories before the scene's own."""
    instances = scene.metadata.get("instances", [])
    people = [i for i in instances if _is_person(i)]
    if not people:
        return _recipe_scheme(scene, sources)
    names, skeleton = people[0].get("keypoint_names"), people[0].get("keypoint_skeleton", [])
    if not isinstance(names, list) or not names or not all(isinstance(n, str) for n in names):
        raise ExportError(f"{scene.path.name}: a person's keypoint_names {str(names)[:80]} is not "
                          "a list of names")
    if not isinstance(skeleton, list) or not all(
            isinstance(e, list) and len(e) == 2 and all(isinstance(i, int) for i in e)
            for e in skeleton):
        raise ExportError(f"{scene.path.name}: a person's keypoint_skeleton {str(skeleton)[:80]} "
                          "is not a list of [i, j] pairs")
    base = None if len(people) == len(instances) else _recipe_scheme(scene, sources)
    return PersonScheme(base, names, skeleton)


def _recipe_scheme(scene: Scene, sources=None) -> CategoryScheme:
    """The scheme of ``scene``'s recipe (module doc); ``sources``: asset-source paths given on
    the command line, searched for categories before the scene's own."""
    meta, flags = scene.metadata, scene.metadata.get("flags", {})
    instances = meta.get("instances", [])
    if meta["metadata"].get("semantic_classes"):
        return CategoryScheme("semantic", list(meta["metadata"]["semantic_classes"])[1:],
                              "object")
    if scene.recipe == "movi_a":
        return CategoryScheme("shape", SHAPES, "shape")
    if instances and all("shape" in i for i in instances if not _is_person(i)):
        return CategoryScheme("shape", KUBASIC_SHAPES, "shape")
    if sources or any(k in flags for k in ("objects_source", "objects", "collection_limit")):
        from kubric.datasets.exports.scenes import objects_sources
        names = set()
        for source in objects_sources(flags, sources or ()):
            names.update(source.categories)
        if names:
            return CategoryScheme("asset category", sorted(names), "object")
    return CategoryScheme("object", ["object"], "object")


__all__ = ["CategoryScheme", "PersonScheme", "scheme_for"]

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

Extending: a scheme's :meth:`CategoryScheme.annotation_extras` returns fields added to each
annotation. Person keypoints (scenes with characters) belong there: a scheme that adds the
``person`` category with COCO's ``keypoints`` names and ``skeleton`` to :attr:`categories` and
returns ``keypoints`` / ``num_keypoints`` for a character's instance.
"""

from __future__ import annotations

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


def scheme_for(scene: Scene, sources=None) -> CategoryScheme:
    """The scheme of ``scene``'s recipe (module doc); ``sources``: asset-source paths given on
    the command line, searched for categories before the scene's own."""
    from kubric.assets.clevr import KUBASIC_SHAPES, SHAPES
    meta, flags = scene.metadata, scene.metadata.get("flags", {})
    instances = meta.get("instances", [])
    if meta["metadata"].get("semantic_classes"):
        return CategoryScheme("semantic", list(meta["metadata"]["semantic_classes"])[1:],
                              "object")
    if scene.recipe == "movi_a":
        return CategoryScheme("shape", SHAPES, "shape")
    if instances and all("shape" in i for i in instances):
        return CategoryScheme("shape", KUBASIC_SHAPES, "shape")
    if sources or any(k in flags for k in ("objects_source", "objects", "collection_limit")):
        from kubric.datasets.exports.scenes import objects_sources
        names = set()
        for source in objects_sources(flags, sources or ()):
            names.update(source.categories)
        if names:
            return CategoryScheme("asset category", sorted(names), "object")
    return CategoryScheme("object", ["object"], "object")


__all__ = ["CategoryScheme", "scheme_for"]

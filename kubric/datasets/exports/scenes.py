"""What every export reads: the complete scene directories of a dataset folder, their metadata,
the stable id scheme, the asset sources that hold their meshes, and the errors they raise.

Ids (stable across shards: a scene's ids depend on its seed alone, never on what else is
exported with it, so COCO files exported from disjoint sets of scenes merge without clashes):

* ``image_id`` = ``seed · 10⁴ + i`` for image ``i`` of the scene: frame (view) ``i`` (0-based
  file index) of a one-camera scene; in a camera-rig scene (``cameras=stereo|ring|random``) frame ``t``
  of camera ``c`` (0 = the reference, in ``metadata.camera.rig.cameras`` order) is image
  ``i = c · T + t`` (T frames), so the reference camera's ids are those of a one-camera scene;
* annotation ``id`` = ``image_id · 10⁴ + k`` for segmentation label ``k`` (instance ``k − 1``).

Images and labels must therefore stay below 10⁴ per scene (cameras × frames; the recipes' default
bounds keep them there); the largest id, for seed 2³² − 1, is about 4.3·10¹⁷ (< 2⁶³).

Camera rigs: :func:`camera_views` gives one :class:`Scene` per camera, each reading its own
layers (``NAME_<layer>``) and seeing its own camera record and per-instance fields as the
reference camera's (``metadata.camera.rig.views[NAME]``, ``instances[k].cameras[NAME]``), so an
export written for one camera writes every camera of a rig by looping over them.
"""

from __future__ import annotations

import dataclasses
import pathlib

import numpy as np

from kubric import asset_tools
from kubric.errors import InputError
from kubric.io import scene_dir
from kubric.io.json_io import read_json
from kubric.io.layers import read_frame, read_layer
from kubric.io.stored_schema import stored_schema

ID_BASE = 10_000


class ExportError(InputError):
    """Bad input to an export (one line naming the bad value)."""


@dataclasses.dataclass
class Scene:
    path: pathlib.Path
    relative: str          # the scene folder relative to the export's root ("" for the root)
    metadata: dict
    camera_name: str = ""  # a camera-rig scene's camera ("" for a one-camera scene)
    camera_index: int = 0  # its position in the rig, 0 = the reference camera
    formats: dict | None = None  # the scene's own layer formats (a rig's per-camera layers)

    @property
    def prefix(self) -> str:
        """Prefix of this camera's layer names: ``NAME_`` for a rig's further camera, else ''."""
        return f"{self.camera_name}_" if self.camera_index else ""

    def read_layer(self, name: str, **kwargs) -> np.ndarray:
        """(T, H, W, C) layer ``name`` as this camera sees it."""
        return read_layer(self.path, self.prefix + name, formats=self.formats, **kwargs)

    def read_frame(self, name: str, frame: int) -> np.ndarray:
        """(H, W, C) frame ``frame`` of layer ``name`` as this camera sees it."""
        return read_frame(self.path, self.prefix + name, frame, formats=self.formats)

    def image_index(self, frame: int) -> int:
        """The scene's image index of this camera's ``frame`` (module doc: c · T + frame)."""
        index = self.camera_index * self.num_frames + int(frame)
        if index >= ID_BASE:
            raise ExportError(f"{self.path.name}: camera {self.camera_name!r} frame {frame} is "
                              f"image {index}; the id scheme holds cameras × frames < {ID_BASE}")
        return index

    @property
    def seed(self) -> int:
        return int(self.metadata["metadata"]["seed"])

    @property
    def recipe(self) -> str:
        return str(self.metadata.get("flags", {}).get("recipe", ""))

    @property
    def num_frames(self) -> int:
        return int(self.metadata["metadata"]["num_frames"])

    @property
    def resolution(self) -> tuple[int, int]:
        w, h = self.metadata["metadata"]["resolution"]
        return int(w), int(h)

    def file(self, name: str) -> str:
        """``name`` (a file of the scene) relative to the export's root, with ``/``."""
        return f"{self.relative}/{name}" if self.relative else name


def camera_views(scene: Scene) -> list[Scene]:
    """One :class:`Scene` per camera of a camera-rig scene, the reference (``scene`` itself,
    named) first; ``[scene]`` for a one-camera scene (module doc)."""
    rig = scene.metadata["camera"].get("rig")
    if not rig:
        return [scene]
    schema = stored_schema(scene.path)
    if schema is None:
        raise ExportError(f"{scene.path.name}: a camera-rig scene without its schema.json (its "
                          "per-camera layers are declared there)")
    views = []
    for index, name in enumerate(rig["cameras"]):
        meta = scene.metadata
        if index:
            try:
                meta = {**meta, "camera": rig["views"][name], "instances": [
                    {**inst, **inst["cameras"][name]} for inst in meta.get("instances", [])]}
            except KeyError as err:
                raise ExportError(f"{scene.path.name}: metadata.json has no record of rig "
                                  f"camera {name!r} ({err})") from None
        views.append(dataclasses.replace(scene, metadata=meta, camera_name=name,
                                         camera_index=index, formats=schema.layers))
    return views


def image_id(seed: int, frame: int) -> int:
    if not 0 <= frame < ID_BASE:
        raise ExportError(f"frame index {frame} does not fit the id scheme (0 ≤ frame < {ID_BASE})")
    return int(seed) * ID_BASE + int(frame)


def annotation_id(image: int, label: int) -> int:
    if not 0 < label < ID_BASE:
        raise ExportError(f"segmentation label {label} does not fit the id scheme (1 ≤ label < "
                          f"{ID_BASE})")
    return int(image) * ID_BASE + int(label)


def find_scenes(root) -> tuple[list[pathlib.Path], int]:
    """(complete scene directories under ``root``, or ``root`` itself; number of incomplete
    ones skipped). One-line ExportError when ``root`` is not a folder or holds no scene, and a
    DuplicateSeedError when two scenes share a seed (their ids would clash)."""
    root = pathlib.Path(root)
    if not root.is_dir():
        raise ExportError(f"{str(root)!r} is not a directory (expected a folder of scene_* "
                          "directories, or one scene directory)")
    if scene_dir.is_complete(root):
        return [root], 0
    complete, incomplete = scene_dir.survey(root)
    if not complete:
        raise ExportError(f"{str(root)!r} holds no complete scene directory (scene_* with "
                          f"{scene_dir.SUCCESS_FILE})")
    scene_dir.check_unique_seeds((load_scene(root, p).seed, p) for p in complete)
    return complete, incomplete


def load_scene(root: pathlib.Path, path: pathlib.Path) -> Scene:
    meta_file = path / scene_dir.METADATA_FILE
    try:
        metadata = read_json(meta_file)
    except FileNotFoundError:
        raise ExportError(f"scene {str(path)!r} has no {scene_dir.METADATA_FILE}") from None
    for section, key in (("metadata", "seed"), ("metadata", "num_frames"),
                         ("metadata", "resolution"), ("camera", "matrices_world")):
        if key not in metadata.get(section, {}):
            raise ExportError(f"{str(meta_file)!r} lacks {section}.{key}")
    relative = "" if path == root else path.relative_to(root).as_posix()
    return Scene(path, relative, metadata)


def objects_sources(flags: dict, extra=()) -> list:
    """The asset sources a scene's objects came from: the ``extra`` ones given (paths), then
    those the scene's options name (``objects_source``, ``objects``), else the default of the
    recipe: the converted ``pybullet_data`` collection for those with the option
    ``collection_limit`` (MOVi), KuBasic for the others with an ``objects_source`` option (svr,
    complex_brdf, vbr)."""
    import kubric as kb

    out = [kb.AssetSource(p) for p in extra]
    for key in ("objects_source", "objects"):
        value = flags.get(key)
        if isinstance(value, str) and value:
            out.append(kb.AssetSource(value))
    if "collection_limit" in flags and flags.get("objects_source") is None:
        out.append(asset_tools.ensure_pybullet_collection(limit=flags.get("collection_limit")))
    elif "objects_source" in flags and flags.get("objects_source") is None:
        out.append(_kubasic(flags))  # svr, complex_brdf, vbr: KuBasic is their objects' source
    return out


def _kubasic(flags: dict):
    import kubric as kb

    kubasic = flags.get("kubasic_source")
    return kb.AssetSource(kubasic) if kubasic else asset_tools.ensure_kubasic()


def model_sources(flags: dict, extra=()) -> list:
    """:func:`objects_sources` plus KuBasic (``kubasic_source``, else the locally built one):
    every source whose meshes a scene's instances may use."""
    return objects_sources(flags, extra) + [_kubasic(flags)]


__all__ = ["ExportError", "ID_BASE", "Scene", "annotation_id", "camera_views", "find_scenes",
           "image_id",
           "load_scene", "model_sources",
           "objects_sources"]

"""Option checks and asset-source opening shared by every recipe family (MOVi, multi-view)."""

from __future__ import annotations

from kubric import asset_tools
from kubric.assets.asset_source import ManifestError
from kubric.assets.remote_source import RemoteSourceError, is_remote, local_path
from kubric.io import storage
from kubric.pipeline import OptionError


def source_location(value):
    """Option converter for an asset source: a local folder / ``manifest.json`` (a ``Path``,
    which must exist) or the URL of one (a normalised ``str``: ``https://``, ``s3://``, ``gs://``,
    any fsspec URL; ``file://`` URLs become paths)."""
    import pathlib

    if not isinstance(value, (str, pathlib.Path)) or not str(value).strip():
        raise ValueError("expected a path or URL")
    if is_remote(str(value)):
        try:
            return storage.normalise(str(value))
        except storage.StorageError as err:
            raise ValueError(str(err)) from None
    path = pathlib.Path(local_path(str(value))).expanduser()
    try:
        exists = path.exists()
    except (OSError, ValueError) as err:  # a name too long, a NUL byte, ...
        raise ValueError(f"not a usable path ({' '.join(str(err).split())[:200]})") from None
    if not exists:
        raise ValueError("path does not exist")
    return path


source_location.allowed = ("an existing asset-source folder / manifest.json, or its URL "
                           "(https://, s3://, gs://, ...)")
source_location.__name__ = "path|URL"


def open_existing_source(path, what: str):
    """The :class:`~kubric.AssetSource` at ``path`` (option ``what``, a path or URL); one line if
    it cannot be fetched, is malformed or is empty."""
    import kubric as kb

    try:
        source = kb.AssetSource(path)
    except (RemoteSourceError, ManifestError) as err:
        raise OptionError(f"{what} {str(path)!r}: {err}") from None
    if not len(source):
        raise OptionError(f"{what} {str(path)!r} holds no assets")
    return source


def kubasic_sources(kubasic_source) -> dict:
    """``{"kubasic": source}``: the folder given by the option, else the locally built KuBasic."""
    if kubasic_source is not None:
        return {"kubasic": open_existing_source(kubasic_source, "kubasic_source")}
    return {"kubasic": asset_tools.ensure_kubasic()}


def check_source_options(recipe, names=None) -> None:
    """Every asset-source option (``*_source``, plus ``names``) that is set names a folder with
    ``manifest.json`` (or that file) or is a URL; raises OptionError (one line) otherwise."""
    for name, value in recipe.values.items():
        if name == "material_source":  # not an asset source: material_options checks it
            continue
        if (name.endswith("_source") or name in (names or ())) and value is not None:
            if isinstance(value, str):  # a URL: fetched (and checked) when the source opens
                continue
            manifest = value / "manifest.json" if value.is_dir() else value
            if not manifest.is_file() or manifest.name != "manifest.json":
                raise OptionError(f"{recipe.name}: option {name}={str(value)!r} is not an asset "
                                  "source (a folder with manifest.json)")


def min_max_pairs(recipe) -> list[tuple[str, str]]:
    """(``min_X``, ``max_X``) option pairs of a recipe, which must be ordered."""
    return [(a, a.replace("min_", "max_", 1)) for a in recipe.options if a.startswith("min_")
            and a.replace("min_", "max_", 1) in recipe.options]


def check_min_max(recipe) -> None:
    """Every ``min_X`` ≤ ``max_X``; raises OptionError (one line) otherwise."""
    for low, high in min_max_pairs(recipe):
        if recipe.values[low] > recipe.values[high]:
            raise OptionError(f"{recipe.name}: option {low}={recipe.values[low]} must be ≤ "
                              f"{high}={recipe.values[high]}")


def annotate_instances(scene, layers: dict, candidates, order=None, before_relabel=None) -> list:
    """The instance annotations every recipe makes, in this order: visibility per frame of every
    asset → the instance list (``order(candidates)``, by default the candidates sorted by visible
    pixels, hidden ones dropped) → ``before_relabel(instances)`` (e.g. point tracks, which need
    the renderer's labels) → the segmentation relabelled to that list → 2D boxes. Returns the
    instance list."""
    import kubric as kb

    kb.compute_visibility(layers["segmentation"], scene.assets)
    instances = list((order or kb.post_processing.visible_sorted)(candidates))
    if before_relabel is not None:
        before_relabel(instances)
    layers["segmentation"] = kb.adjust_segmentation_idxs(layers["segmentation"], scene.assets,
                                                         instances)
    kb.compute_bboxes(layers["segmentation"], instances)
    return instances


def scene_documents(recipe, scene, seed: int, instances, collisions=None, **metadata) -> tuple:
    """(``metadata.json``, ``events.json``) of a scene: the recipe's flags, the scene metadata
    (``metadata`` adds recipe fields), the camera per frame, the instances (in the order of the
    relabelled segmentation) and the collision events between them."""
    import kubric as kb

    meta = kb.get_scene_metadata(scene, seed=int(seed), num_instances=len(instances), **metadata)
    document = {"flags": recipe.flags(seed), "metadata": meta,
                "camera": kb.get_camera_info(scene.camera),
                "instances": kb.get_instance_info(scene, instances)}
    events = {"collisions": kb.process_collisions(collisions, scene, instances)
              if collisions is not None else []}
    return document, events

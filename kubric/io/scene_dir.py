"""The scene directory, declared once: its file names, its naming, its completion marker, listing.

A recipe writes one scene per seed into ``ROOT/scene_{seed:08d}/`` (docs: ``docs/scene-format.md``)::

    scene_00000007/
        rgba_00000.png ...           layers (kubric.io.layers, plus the recipe schema's own)
        data_ranges.json             min / max of every scaled layer
        metadata.json                flags, metadata, camera, instances
        events.json                  collisions
        schema.json                  the scene's schema: what every reader needs to read it
        tracks.npz                   point tracks (optional)
        scene.blend, scene.bullet    saved Blender / PyBullet state (optional)
        lasr/                        vbr's LASR sequence (optional)
        _SUCCESS                     written last: the scene is complete

Work in progress lives in ``ROOT/.scene_{seed:08d}.incomplete-{pid}/`` and becomes the final name
in one rename (:mod:`kubric.pipeline.worker`), so a final name is complete or absent. Everything
that reads or writes a scene directory — the writer, worker, runners, packer, viewer, exports,
``kubric inspect`` — takes these names and these tests from here. Paths may be local paths or
URLs (``s3://…``) where noted; URL listing goes through :mod:`kubric.io.storage`.
"""

from __future__ import annotations

import json
import os
import pathlib
import re

from kubric.errors import InputError
from kubric.io import storage
from kubric.io.layers import DATA_RANGES_FILE

METADATA_FILE = "metadata.json"
EVENTS_FILE = "events.json"
TRACKS_FILE = "tracks.npz"
#: the scene's schema document (:mod:`kubric.io.stored_schema`): written by the one writer, read
#: by the packer, viewer, exports and ``kubric inspect`` (no recipe import needed)
SCHEMA_FILE = "schema.json"
#: optional outputs some recipes declare through the writer (``save_state``, ``lasr_export``)
BLEND_FILE = "scene.blend"
BULLET_FILE = "scene.bullet"
LASR_DIR = "lasr"
SUCCESS_FILE = "_SUCCESS"
LOGS_DIR = "logs"
SCENE_PREFIX = "scene_"
#: ``scene_{seed:08d}``; seeds above 99,999,999 simply have more digits
SCENE_RE = re.compile(r"^scene_(\d{8,})$")
#: the worker's hidden work directory of one scene and one process
WORK_RE = re.compile(r"^\.(scene_\d{8,})\.incomplete-(\d+)$")


def scene_name(seed: int) -> str:
    """``scene_{seed:08d}``; ValueError (one line) for a seed that is not an integer ≥ 0."""
    if isinstance(seed, bool) or not isinstance(seed, int | float) or int(seed) != seed \
            or seed < 0:
        raise ValueError(f"seed must be an integer ≥ 0, got {seed!r}")
    return f"{SCENE_PREFIX}{int(seed):08d}"


def seed_of(name) -> int | None:
    """The seed in a scene directory's name (``scene_00000007`` → 7; a path's last part), or
    None when the name is not a scene name."""
    match = SCENE_RE.match(pathlib.PurePosixPath(str(name).rstrip("/")).name)
    return int(match.group(1)) if match else None


def work_dir_name(seed: int, pid: int) -> str:
    """The hidden work directory of scene ``seed`` while process ``pid`` writes it."""
    return f".{scene_name(seed)}.incomplete-{int(pid)}"


def parse_work_dir(name: str) -> tuple[str, int] | None:
    """(scene name, pid) of a work directory's name, or None."""
    match = WORK_RE.match(name)
    return (match.group(1), int(match.group(2))) if match else None


def is_complete(scene) -> bool:
    """True when the scene directory ``scene`` (a path or URL) holds ``_SUCCESS``."""
    if storage.is_url(str(scene)):
        return storage.isfile(storage.join(str(scene), SUCCESS_FILE))
    return (pathlib.Path(scene) / SUCCESS_FILE).is_file()


def write_success(directory, **info) -> pathlib.Path:
    """Mark ``directory`` complete: ``_SUCCESS`` (the JSON of ``info``: recipe, seed, seconds)
    written atomically — a temporary file renamed into place. The one writer of the marker."""
    marker = pathlib.Path(directory) / SUCCESS_FILE
    tmp = marker.with_name(f".{SUCCESS_FILE}.{os.getpid()}.tmp")
    tmp.write_text(json.dumps(info) + "\n")
    os.replace(tmp, marker)
    return marker


def is_scene_name(name: str) -> bool:
    """A final scene directory's name (``scene_{seed:08d}``)."""
    return SCENE_RE.match(name) is not None


def complete_scenes(root) -> list[str]:
    """Sorted names of the complete scene directories directly under ``root`` (a path or URL):
    the only ones a reader (pack, inspect, export, resume) may treat as data."""
    root = str(root)
    if not storage.is_url(root):
        if not os.path.isdir(root):
            return []
        return sorted(n for n in os.listdir(root)
                      if is_scene_name(n) and os.path.isfile(os.path.join(root, n, SUCCESS_FILE)))
    return storage.complete_scenes(root, SUCCESS_FILE)


def survey(root: pathlib.Path) -> tuple[list[pathlib.Path], int]:
    """(complete scene directories under local ``root`` in name order, number of incomplete
    ones). A folder holding ``_SUCCESS`` counts as complete whatever its name; an incomplete
    ``scene_*`` folder or a worker's work directory counts as incomplete; other folders
    (``logs``) are ignored."""
    complete, incomplete = [], 0
    for entry in sorted(pathlib.Path(root).iterdir()):
        if not entry.is_dir():
            continue
        if is_complete(entry):
            complete.append(entry)
        elif entry.name.startswith(SCENE_PREFIX) or parse_work_dir(entry.name):
            incomplete += 1
    return complete, incomplete


def scenes_under(root) -> list[pathlib.Path]:
    """``[root]`` when ``root`` is itself a complete scene, else its complete scene directories
    (sorted); FileNotFoundError / ValueError (one line) when it is not a directory or holds none."""
    root = pathlib.Path(root)
    if not root.is_dir():
        raise FileNotFoundError(f"{str(root)!r} is not a directory")
    found = [root] if is_complete(root) else survey(root)[0]
    if not found:
        raise InputError(f"{str(root)!r} holds no complete scene directory (with {SUCCESS_FILE})")
    return found


class DuplicateSeedError(InputError):
    """Two complete scenes with one seed (a copy, a symlink, a re-render under another name)."""


def check_unique_seeds(pairs) -> None:
    """Raise :class:`DuplicateSeedError` (one line naming both) when two of the ``(seed,
    location)`` pairs share a seed: every id an output derives from a seed (COCO ids, BOP scene
    folders, a packed example's key) would clash. Readers call it before writing anything."""
    seen: dict[int, str] = {}
    for seed, location in pairs:
        if seed in seen:
            raise DuplicateSeedError(
                f"scenes {seen[seed]!r} and {str(location)!r} have the same seed {seed} (a copy, "
                "a symlink or a re-render under another name); keep one of them")
        seen[seed] = str(location)


def looks_like_scene(path: pathlib.Path) -> bool:
    """A folder that is, or was meant to be, a scene directory (complete or not): what a
    browser of scene folders lists, so that a broken scene is shown as broken."""
    path = pathlib.Path(path)
    return (path / METADATA_FILE).is_file() or (path / SUCCESS_FILE).is_file() or \
        path.name.startswith(SCENE_PREFIX)


__all__ = ["BLEND_FILE", "BULLET_FILE", "DATA_RANGES_FILE", "DuplicateSeedError", "EVENTS_FILE", "LASR_DIR",
           "LOGS_DIR", "METADATA_FILE", "SCENE_PREFIX", "SCENE_RE", "SCHEMA_FILE", "SUCCESS_FILE",
           "TRACKS_FILE", "WORK_RE", "check_unique_seeds", "complete_scenes",
           "is_complete", "is_scene_name", "looks_like_scene", "parse_work_dir", "scene_name",
           "scenes_under", "seed_of", "survey", "work_dir_name", "write_success"]

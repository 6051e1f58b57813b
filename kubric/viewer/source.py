"""Where the viewer's data comes from: the :class:`SceneSource` interface and its scene-directory
implementation.

The server only talks to a :class:`SceneSource`; a packed-dataset backend implements the same
six abstract methods (``names``, ``summary``, ``metadata``, ``events``, ``frame``, ``tracks``)
and plugs in without touching the server or the page.

Scenes are addressed by **name** (the directory name, e.g. ``scene_00000007``), never by a path:
a name must match :data:`NAME_PATTERN` and be one of the names the source found, so nothing in a
URL can reach a file outside the served folder. Every read is read-only.
"""

from __future__ import annotations

import abc
import pathlib
import re
import time

import numpy as np

from kubric.annotations.track_files import read_tracks
from kubric.errors import InputError, KubricError
from kubric.extras import EXTRA_OF, message
from kubric.io.event_h5 import EVENTS_H5_FILE, events_file, read_events
from kubric.io.json_io import read_json
from kubric.io.layers import LAYER_LABELS, LAYERS, LayerFormat, frame_filename, read_frame
from kubric.io.scene_dir import EVENTS_FILE, METADATA_FILE, SCHEMA_FILE, SUCCESS_FILE, TRACKS_FILE
from kubric.io.scene_dir import looks_like_scene as _looks_like_scene
from kubric.io.schema import SchemaError
from kubric.pipeline.recipe import scene_schema

#: a scene name: letters, digits, ``_ . -``, not starting with a dot (no separators, no ``..``)
NAME_PATTERN = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_.\-]{0,199}\Z")
#: the standard layers the viewer shows, in the selector's order (kubric.io.layers.LAYERS)
VIEW_LAYERS = tuple(LAYERS)
#: how often a folder is rescanned for new scenes (seconds)
RESCAN_SECONDS = 2.0


class SceneError(KubricError):
    """A scene that cannot be shown (incomplete, corrupt): the page shows the message."""


class SceneSource(abc.ABC):
    """Read-only access to the scenes of one dataset."""

    @abc.abstractmethod
    def names(self) -> list[str]:
        """Scene names, sorted."""

    @abc.abstractmethod
    def summary(self, name: str) -> dict:
        """One row of the scene list: name, recipe, seed, split, num_instances, num_frames,
        resolution, layers, has_tracks, and ``error`` (None for a good scene)."""

    @abc.abstractmethod
    def metadata(self, name: str) -> dict:
        """The scene's metadata.json content (raises SceneError when absent or unreadable)."""

    @abc.abstractmethod
    def events(self, name: str) -> dict:
        """The scene's events.json content ({"collisions": []} when absent)."""

    @abc.abstractmethod
    def frame(self, name: str, layer: str, index: int) -> np.ndarray:
        """One decoded (H, W, C) frame of a layer (units as in docs/scene-format.md)."""

    @abc.abstractmethod
    def tracks(self, name: str) -> dict | None:
        """The scene's point tracks (``tracks.npz`` fields) or None when it has none."""

    def event_stream(self, name: str, camera: str | None = None) -> dict | None:
        """The scene's event stream ({"x", "y", "t" µs, "p"}, t sorted) — of rig camera
        ``camera`` when given (``events_NAME.h5``) — or None when it has none (default: no
        source holds events)."""
        return None

    def output_root(self, name: str) -> str:
        """The ``--out`` that regenerates the scene in place (shown in its worker command)."""
        return "OUT"

    def formats(self, name: str) -> dict[str, LayerFormat]:
        """The layers a scene may hold and how they are stored (default: the standard ones)."""
        return {n: LAYERS[n] for n in VIEW_LAYERS}

    def vocabulary(self, name: str) -> dict[str, dict]:
        """What the page needs to know of each layer the scene may hold (it keeps no list of
        its own): ``label`` (the selector's text), ``kind`` (its layer kind) and
        ``adjustable_range`` (the page offers a [lo, hi] to draw it over)."""
        return {n: {"label": LAYER_LABELS.get(n, n), "kind": fmt.kind,
                    "adjustable_range": fmt.type.adjustable_range}
                for n, fmt in self.formats(name).items()}

    def check_name(self, name: str) -> str:
        """``name`` when it is a scene of this source; KeyError otherwise."""
        if not isinstance(name, str) or not NAME_PATTERN.match(name) or name not in self.names():
            raise KeyError(f"no scene named {name!r}")
        return name


#: the viewer's layer of the reference camera's accumulated events (events.h5); a rig camera
#: NAME's is ``NAME_events`` (events_NAME.h5), as its other layers are ``NAME_<layer>``
EVENTS_LAYER = "events"


def event_layer(camera: str | None = None) -> str:
    """The viewer's layer of ``camera``'s accumulated events (None: the reference camera)."""
    return f"{camera}_{EVENTS_LAYER}" if camera else EVENTS_LAYER


def is_event_layer(layer: str) -> bool:
    """Whether ``layer`` is drawn from an event stream (:func:`event_layer`)."""
    return layer == EVENTS_LAYER or (layer.endswith("_" + EVENTS_LAYER)
                                     and len(layer) > len(EVENTS_LAYER) + 1)


def event_layer_camera(layer: str) -> str | None:
    """The rig camera whose stream an event layer draws; None for the reference camera's."""
    return None if layer == EVENTS_LAYER else layer[:-len("_" + EVENTS_LAYER)]


#: the most frames (views) a scene may claim in the viewer
MAX_FRAMES = 100_000


def frame_count_error(name: str, count, directory, formats: dict, layers: list) -> str | None:
    """Why ``metadata.num_frames`` = ``count`` cannot be shown (not a whole number in
    1..:data:`MAX_FRAMES`, or the last frame of the first layer is missing), or None."""
    if count is None:
        return None
    if isinstance(count, bool) or not isinstance(count, int) or count < 1:
        return f"{name}/metadata.json: num_frames {str(count)[:40]!r} is not a whole number ≥ 1"
    if count > MAX_FRAMES:
        return f"{name}/metadata.json claims {count} frames; the viewer shows at most {MAX_FRAMES}"
    if layers and not (directory / frame_filename(formats[layers[0]].template,
                                                 count - 1)).is_file():
        return (f"{name}/metadata.json claims {count} frames, but {layers[0]} frame {count - 1} "
                "is missing")
    return None


class DirectorySource(SceneSource):
    """A scene directory (one scene) or a folder whose sub-directories are scenes.

    A folder's scenes are its non-hidden sub-directories holding ``metadata.json`` or
    ``_SUCCESS`` or named ``scene_*``; the hidden work directories of scenes being written are
    left out. Scenes without ``_SUCCESS`` are listed with an error (incomplete)."""

    def __init__(self, path):
        root = pathlib.Path(path).expanduser().resolve()
        if not root.is_dir():
            raise NotADirectoryError(f"{str(path)!r} is not a directory (give a scene "
                                     "directory or a folder of scenes)")
        self.root = root
        self.single = _looks_like_scene(root)
        self._names: list[str] = []
        self._scanned = -np.inf
        # name → ((schema.json, metadata.json) mtimes, the layers its schema declares)
        self._own_layers: dict[str, tuple] = {}

    def names(self) -> list[str]:
        """Rescanned at most every :data:`RESCAN_SECONDS`: scenes a running ``kubric generate``
        adds appear in the list."""
        if time.monotonic() - self._scanned >= RESCAN_SECONDS:
            if self.single:
                names = [self.root.name]
            else:
                names = sorted(p.name for p in self.root.iterdir()
                               if p.is_dir() and NAME_PATTERN.match(p.name) and _looks_like_scene(p))
            self._names, self._scanned = names, time.monotonic()
        return self._names

    def directory(self, name: str) -> pathlib.Path:
        self.check_name(name)
        return self.root if self.single else self.root / name

    def output_root(self, name: str) -> str:
        return str(self.directory(name).parent)

    def summary(self, name: str) -> dict:
        directory = self.directory(name)
        row = {"name": name, "recipe": None, "seed": None, "split": None, "num_instances": None,
               "num_frames": None, "resolution": None, "layers": [], "has_tracks": False,
               "error": None}
        try:
            meta = self.metadata(name)
        except SceneError as err:
            row["error"] = str(err)
            return row
        flags, info = meta.get("flags", {}), meta.get("metadata", {})
        wrong = [k for k, v in (("flags", flags), ("metadata", info)) if not isinstance(v, dict)]
        if not isinstance(meta.get("instances", []), list):
            wrong.append("instances")
        if wrong:  # an error card for this scene; the rest of the list is unaffected
            row["error"] = (f"{name}/metadata.json: {', '.join(map(repr, wrong))} has the wrong "
                            "shape (expected an object / a list)")
            return row
        row.update(recipe=flags.get("recipe"), seed=flags.get("seed", info.get("seed")),
                   split=flags.get("split") or info.get("split"),
                   num_instances=len(meta.get("instances", [])),
                   num_frames=info.get("num_frames"), resolution=info.get("resolution"),
                   layers=[n for n, fmt in self.formats(name).items()
                           if (directory / frame_filename(fmt.template, 0)).is_file()],
                   has_tracks=(directory / TRACKS_FILE).is_file())
        if (directory / EVENTS_H5_FILE).is_file():  # drawn as accumulated event frames
            row["layers"].append(event_layer())
        for path in sorted(directory.glob("events_*.h5")):  # a rig's further cameras' streams
            row["layers"].append(event_layer(path.stem[len("events_"):]))
        frames = frame_count_error(name, row["num_frames"], directory, self.formats(name),
                                   row["layers"])
        if frames is not None:  # a count the files do not back: never sent to the page
            row["num_frames"], row["error"] = None, frames
        elif not (directory / SUCCESS_FILE).is_file():
            row["error"] = f"incomplete scene: {name} has no {SUCCESS_FILE} (still being " \
                           "written, or its worker failed)"
        return row

    def metadata(self, name: str) -> dict:
        return self._json(name, METADATA_FILE, required=True)

    def events(self, name: str) -> dict:
        return self._json(name, EVENTS_FILE, required=False) or {"collisions": []}

    def _json(self, name: str, filename: str, required: bool):
        path = self.directory(name) / filename
        if not path.is_file():
            if required:
                raise SceneError(f"{name} has no {filename}")
            return None
        try:
            data = read_json(path)
        except (ValueError, OSError) as err:
            raise SceneError(f"{name}/{filename} is unreadable: {err}") from None
        if not isinstance(data, dict):
            raise SceneError(f"{name}/{filename} is not a JSON object")
        return data

    def formats(self, name: str) -> dict[str, LayerFormat]:
        """The layers a scene may hold: the standard ones the viewer draws, then those its
        schema declares (klevr's semantic labels, texture_nerf's bands, a file recipe's own):
        the schema the scene stores, else its recipe's; none when neither is known."""
        directory = self.directory(name)
        stamp = tuple(_mtime(directory / f) for f in (SCHEMA_FILE, METADATA_FILE))
        cached = self._own_layers.get(name)
        if cached is None or cached[0] != stamp:  # read again only when a file changed
            cached = self._own_layers[name] = (stamp, _scene_layers(directory))
        return {**super().formats(name), **cached[1]}

    def frame(self, name: str, layer: str, index: int) -> np.ndarray:
        formats = self.formats(name)
        if layer not in formats:
            raise KeyError(f"unknown layer {layer!r}; allowed: {', '.join(formats)}")
        try:
            return read_frame(self.directory(name), layer, index, formats=formats)
        except FileNotFoundError as err:
            raise KeyError(str(err)) from None
        except (ValueError, OSError, RuntimeError) as err:  # truncated / corrupt files
            raise SceneError(f"{name}: cannot decode frame {index} of {layer}: {err}") from None

    def event_stream(self, name: str, camera: str | None = None) -> dict | None:
        path = self.directory(name) / (events_file(camera) if camera else EVENTS_H5_FILE)
        if not path.is_file():
            return None
        try:
            return read_events(path)
        except ModuleNotFoundError as err:
            raise SceneError(message(err.name if err.name in EXTRA_OF else "h5py",
                                       f"showing {name}'s events")) from None
        except InputError as err:
            raise SceneError(f"{name}/{path.name} is unreadable: {err}") from None

    def tracks(self, name: str) -> dict | None:
        directory = self.directory(name)
        if not (directory / TRACKS_FILE).is_file():
            return None
        try:
            return read_tracks(directory)
        except (ValueError, OSError) as err:
            raise SceneError(f"{name}/tracks.npz is unreadable: {err}") from None


def _mtime(path: pathlib.Path) -> int | None:
    try:
        return path.stat().st_mtime_ns
    except OSError:
        return None


def _scene_layers(directory: pathlib.Path) -> dict[str, LayerFormat]:
    """The layers the scene's schema declares beyond the standard ones ({} when its schema is
    unknown here or unreadable: the scene shows its standard layers)."""
    try:
        return dict(scene_schema(directory).schema.layers)
    except (SchemaError, ValueError, OSError):
        return {}

"""The base of everything that can be placed in a scene: :class:`Asset`.

An asset has a ``uid`` (``name``, ``name.001``, ``name.002``, ... like Blender), unique in its scene:
the scene numbers it when it joins (see :mod:`kubric.core.uids`; before that the uid is the name),
validated properties (see :mod:`kubric.core.traits`), keyframes, and a link to the views (simulator,
renderer) of every scene it belongs to. Assigning a property notifies each of those views once via
``view.on_change(asset, name, value)``; ``keyframe_insert`` notifies via
``view.on_keyframe(asset, name, frame)`` and ``keyframe_delete`` via
``view.on_keyframe_delete(asset, name, frame)``. Scripts may also register callbacks with
upstream Kubric's (traitlets') ``asset.observe(handler, names, type="change" | "keyframe")``.

Keyframe interpolation (``get_value_at``, ``at_frame``, ``get_values_over_time``): vectors and
scalars interpolate **linearly**, quaternions by **slerp** (shorter arc), anything else holds the
previous keyframe. Before the first / after the last keyframe the first / last value is held.
Keys may sit at fractional frames (as in upstream Kubric and Blender): rendered frames are whole,
so a fractional key changes what is rendered only through this interpolation (docs/conventions.md).
Renderer views must key Blender with linear interpolation so Blender's motion matches this.
"""

from __future__ import annotations

import contextlib
from collections import defaultdict
from collections.abc import Iterator, Sequence
from typing import Any

import numpy as np

from kubric.core import traits as kt
from kubric.core.quaternion import Quaternion


class Asset(kt.HasProperties):
    """Base class of objects, lights, cameras and materials.

    Keyword-only construction: every keyword must be a property name (or ``name``), else
    ``TypeError`` naming it. ``name`` (default: the class name) is the basis of ``uid``.

    Attributes:
      uid: read-only id, unique in the asset's scene: given by the first scene the asset joins
        (``name``, ``name.001``, ... in joining order); the name while in no scene.
      keyframes: ``{property: {frame: value}}`` (frame: int, or float when fractional).
      linked_objects: ``{view: backend object}``, filled by views.
      scenes: the scenes this asset was added to.
    """

    background = kt.Property(False, kt.as_bool(), "part of the background (floor, dome, camera)")
    metadata = kt.Property(dict, kt.as_dict(), "free-form metadata carried to the output")

    def __init__(self, *, name: str | None = None, **kwargs):
        if name is not None and (not isinstance(name, str) or not name):
            raise TypeError(f"{type(self).__name__}.name must be a non-empty string, got {name!r}")
        self._name = name or type(self).__name__
        self._uid: str | None = None  # set by the first scene the asset joins
        self.linked_objects: dict[Any, Any] = {}
        self.scenes: list = []
        self.keyframes: dict[str, dict[int | float, Any]] = defaultdict(dict)
        self._init_properties(kwargs)

    @property
    def name(self) -> str:
        return self._name

    @property
    def uid(self) -> str:
        return self._name if self._uid is None else self._uid

    @property
    def active_scene(self):
        """The first scene this asset was added to (or None)."""
        return self.scenes[0] if self.scenes else None

    # ------------------------------------------------------------------ views
    @property
    def views(self) -> tuple:
        """Every view of every scene this asset belongs to, and of every scene or asset whose
        property holds it (a material assigned after its object was added), each once."""
        seen: dict[int, Any] = {}
        self._collect_views(seen, set())
        return tuple(seen.values())

    def _collect_views(self, seen: dict[int, Any], visited: set[int]) -> None:
        if id(self) in visited:
            return
        visited.add(id(self))
        for scene in self.scenes:
            for view in scene.views:
                seen.setdefault(id(view), view)
        for owner, _ in self.owners:
            if isinstance(owner, Asset):
                owner._collect_views(seen, visited)
            else:  # the scene
                for view in owner.views:
                    seen.setdefault(id(view), view)

    def _on_property_set(self, name: str, value: Any) -> None:
        for view in self.views:
            view.on_change(self, name, value)

    # ------------------------------------------------------------------ observers
    def observe(self, handler, names=None, type: str = "change") -> None:
        """Call ``handler(change)`` after each assignment (``type="change"``; ``change`` has
        ``name``, ``owner``, ``old``, ``new``, ``type``) or ``keyframe_insert`` (``"keyframe"``;
        ``name``, ``owner``, ``frame``, ``type``) of the properties ``names`` (one name, a list,
        or None for all) — upstream Kubric's traitlets observer API."""
        if type not in ("change", "keyframe"):
            raise ValueError(f"{self.uid}.observe: type must be 'change' or 'keyframe', got "
                             f"{type!r}")
        if not callable(handler):
            raise TypeError(f"{self.uid}.observe: handler must be callable, got {handler!r}")
        wanted = None if names is None else ((names,) if isinstance(names, str) else tuple(names))
        for name in wanted or ():
            self.get_property(name)  # raises naming the allowed properties
        self.__dict__.setdefault("_observers", []).append((handler, wanted, type))

    def unobserve(self, handler, names=None, type: str = "change") -> None:
        """Remove a callback registered with the same arguments by :meth:`observe`."""
        wanted = None if names is None else ((names,) if isinstance(names, str) else tuple(names))
        observers = self.__dict__.get("_observers", [])
        if (handler, wanted, type) not in observers:
            raise ValueError(f"{self.uid}: no observer {handler!r} for {wanted} ({type})")
        observers.remove((handler, wanted, type))

    def _notify_observers(self, type: str, name: str, **fields) -> None:
        for handler, wanted, kind in list(self.__dict__.get("_observers", ())):
            if kind == type and (wanted is None or name in wanted):
                handler(Change(name=name, owner=self, type=type, **fields))

    def _set_property(self, name: str, value: Any, notify: bool = True) -> None:
        old = self._values.get(name)
        super()._set_property(name, value, notify)
        if notify and not self._silent:
            self._notify_observers("change", name, old=old, new=self._values[name])

    # ------------------------------------------------------------------ keyframes
    def _key_frame(self, frame) -> int | float:
        """A keyframe's frame: an integer, or a finite real number as upstream / Blender accept
        (a key at a fractional time); an integral float (``1.0``) is the integer frame."""
        if isinstance(frame, bool) or not isinstance(frame, (int, float, np.integer,
                                                             np.floating)):
            raise TypeError(f"{self.uid}: keyframe frame must be a number (int or float), got "
                            f"{frame!r}")
        value = float(frame)
        if not np.isfinite(value):
            raise ValueError(f"{self.uid}: keyframe frame must be finite, got {frame!r}")
        return int(value) if value.is_integer() else value

    def keyframe_insert(self, name: str, frame: int | float) -> None:
        """Store the current value of property ``name`` at ``frame`` and notify every view.

        ``frame`` may be fractional (``1.5``: halfway between frames 1 and 2); an integral float
        is that integer frame, so ``keyframe_insert(n, 1.0)`` and ``(n, 1)`` are the same key.
        Values between keys interpolate as the module doc says, fractional keys included."""
        self.get_property(name)  # raises KeyError naming the allowed properties
        frame = self._key_frame(frame)
        self.keyframes[name][frame] = self._values[name]
        for view in self.views:
            view.on_keyframe(self, name, frame)
        self._notify_observers("keyframe", name, frame=frame)

    def keyframe_delete(self, name: str, frame: int | float) -> None:
        """Remove the keyframe of ``name`` at ``frame`` and notify every view; a missing one is a
        ``KeyError`` naming the frames that exist."""
        self.get_property(name)
        frame = self._key_frame(frame)
        frames = self.keyframes.get(name, {})
        if frame not in frames:
            raise KeyError(f"{self.uid} has no keyframe of {name!r} at frame {frame}; "
                           f"keyed frames: {sorted(frames)}")
        del frames[frame]
        for view in self.views:
            view.on_keyframe_delete(self, name, frame)

    def get_value_at(self, name: str, frame: float, interpolation: str | None = None):
        """Value of ``name`` at a (possibly fractional) frame, interpolated between keyframes.

        ``interpolation`` defaults to the property's own (linear / slerp / constant); pass
        ``"constant"`` or ``"nearest"`` to override.
        """
        prop = self.get_property(name)
        keys = self.keyframes.get(name)
        if not keys:
            return self._values[name]
        if frame in keys:
            return keys[frame]
        frames = sorted(keys)
        if frame <= frames[0]:
            return keys[frames[0]]
        if frame >= frames[-1]:
            return keys[frames[-1]]
        right = int(np.searchsorted(frames, frame))
        f0, f1 = frames[right - 1], frames[right]
        v0, v1 = keys[f0], keys[f1]
        mode = interpolation or prop.interpolation
        t = (frame - f0) / (f1 - f0)
        if mode == "constant":
            return v0
        if mode == "nearest":
            return v0 if t <= 0.5 else v1
        if mode == "slerp":
            q = Quaternion.slerp(Quaternion(v0), Quaternion(v1), t)
            return prop.convert(np.asarray(q), self, name)
        if mode == "linear":
            mixed = (1.0 - t) * np.asarray(v0, dtype=np.float64) + t * np.asarray(v1, np.float64)
            return prop.convert(mixed if np.ndim(mixed) else float(mixed), self, name)
        raise ValueError(f"unknown interpolation {mode!r}; allowed: linear, slerp, constant, "
                         "nearest")

    def get_values_over_time(self, name: str, frames: Sequence[float] | None = None,
                             interpolation: str | None = None) -> np.ndarray:
        """Array of the values at ``frames`` (default: the scene's frame_start..frame_end)."""
        if frames is None:
            scene = self.active_scene
            if scene is None:
                raise ValueError(f"{self.uid} is in no scene: pass frames explicitly")
            frames = range(scene.frame_start, scene.frame_end + 1)
        return np.array([self.get_value_at(name, f, interpolation) for f in frames],
                        dtype=np.float32)

    @contextlib.contextmanager
    def at_frame(self, frame: float | None, interpolation: str | None = None) -> Iterator[Asset]:
        """Temporarily set every keyframed property to its value at ``frame``.

        Views are *not* notified (this is a read-only look at the animation). ``None`` is a no-op.
        """
        if frame is None:
            yield self
            return
        saved = {name: self._values[name] for name in self.keyframes}
        try:
            for name in saved:
                self._values[name] = self.get_value_at(name, frame, interpolation)
            yield self
        finally:
            self._values.update(saved)

    # ------------------------------------------------------------------ identity
    # Identity, not uid: uids are unique per scene only (two scenes may each hold a "Cube"), and
    # an asset's uid is given when it joins its first scene.
    def __hash__(self) -> int:
        return object.__hash__(self)

    def __eq__(self, other) -> bool:
        if not isinstance(other, Asset):
            return NotImplemented
        return self is other

    def __repr__(self) -> str:
        """Upstream Kubric's form, on one line: ``<uid name=... prop=value ...>`` with the name
        and every property sorted by name (arrays shown as lists)."""
        fields = [("name", self._name), *self._values.items()]
        shown = sorted(f"{key}={_short_repr(value)}" for key, value in fields)
        return f"<{self.uid} {' '.join(shown)}>"


class Change(dict):
    """What an :meth:`Asset.observe` handler receives: a dict whose keys are also attributes."""

    def __getattr__(self, key):
        try:
            return self[key]
        except KeyError:
            raise AttributeError(key) from None


def _short_repr(value) -> str:
    if isinstance(value, np.ndarray):
        return repr(value.tolist())
    if isinstance(value, Asset):
        return f"<{value.uid}>"  # a held asset by uid only, so a repr never nests or cycles
    return repr(value)


class UndefinedAsset(Asset):
    """Marker for "not set" (e.g. :class:`UndefinedMaterial`); never joins a scene, so its uid is
    always its name."""

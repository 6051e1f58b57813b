"""Views: how backends (simulator, renderer, ...) follow the scene model.

The model never imports a backend. A backend subclasses :class:`View` (or the table-driven
:class:`TableView`) and links itself to a :class:`~kubric.core.scene.Scene`; from then on the scene
and its assets call, on every linked view:

* ``add_scene(scene)`` — once, when the view is linked (the scene's own settings; by default this
  hands the scene to ``add``);
* ``add(asset)``     — when the view is linked, for every asset already in the scene, and whenever
  an asset is added to the scene (so ``add`` sees assets only, as in upstream Kubric, unless a view
  keeps the default ``add_scene``);
* ``remove(asset)``  — when an asset leaves the scene or the view is unlinked;
* ``on_change(item, name, value)`` — after a property of the scene or of an asset changed;
* ``on_keyframe(asset, name, frame)`` — after ``asset.keyframe_insert(name, frame)``;
* ``on_keyframe_delete(asset, name, frame)`` — after ``asset.keyframe_delete(name, frame)``.

:class:`TableView` turns these calls into look-ups in three tables keyed by model class (resolved
along the class's MRO, so a subclass inherits its parents' rows):

* ``builders``: ``{ModelClass: fn(view, item) -> backend object}``; a row with ``None`` means "this
  backend does not represent this kind of asset" (e.g. lights in a physics engine). A class with no
  row at all is a ``TypeError`` naming the class and what the view supports.
* ``setters``: ``{ModelClass: {property: fn(view, item, backend_obj, value)}}``. Properties without
  a row are ignored by that backend (e.g. colour in a physics engine).
* ``keyframers``: ``{ModelClass: {property: fn(view, item, backend_obj, frame)}}``.
* ``keyframe_deleters``: the same shape, called when a keyframe is deleted.

Adding a property or a backend therefore touches one table, not every asset class.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any, ClassVar

Builder = Callable[[Any, Any], Any]
Setter = Callable[[Any, Any, Any, Any], None]
Keyframer = Callable[[Any, Any, Any, int], None]


class View:
    """Base class of every view. Subclasses set up their backend, then call ``super().__init__``."""

    def __init__(self, scene):
        self.scene = scene
        scene.link_view(self)

    def add_scene(self, scene) -> None:
        """Set up the backend for the scene's own settings; by default ``self.add(scene)``."""
        self.add(scene)

    def add(self, item) -> None:
        """Create the backend counterpart of ``item`` (an asset, or the scene via add_scene)."""

    def remove(self, asset) -> None:
        """Delete the backend counterpart of ``asset``."""

    def on_change(self, item, name: str, value) -> None:
        """Property ``name`` of ``item`` (scene or asset) now has ``value``."""

    def on_keyframe(self, asset, name: str, frame: int) -> None:
        """``asset`` stored a keyframe of ``name`` at ``frame`` (value in ``asset.keyframes``)."""

    def on_keyframe_delete(self, asset, name: str, frame: int) -> None:
        """``asset`` deleted its keyframe of ``name`` at ``frame``."""


def _resolve(table: Mapping[type, Any], cls: type) -> tuple[bool, Any]:
    for klass in cls.__mro__:
        if klass in table:
            return True, table[klass]
    return False, None


def _merged(table: Mapping[type, Mapping[str, Any]], cls: type) -> dict[str, Any]:
    merged: dict[str, Any] = {}
    for klass in reversed(cls.__mro__):
        merged.update(table.get(klass, {}))
    return merged


class TableView(View):
    """A view driven by the ``builders`` / ``setters`` / ``keyframers`` tables (see module doc)."""

    builders: ClassVar[Mapping[type, Builder | None]] = {}
    setters: ClassVar[Mapping[type, Mapping[str, Setter]]] = {}
    keyframers: ClassVar[Mapping[type, Mapping[str, Keyframer]]] = {}
    keyframe_deleters: ClassVar[Mapping[type, Mapping[str, Keyframer]]] = {}

    def __init_subclass__(cls, **kwargs):
        super().__init_subclass__(**kwargs)
        cls._row_cache = {}

    def _rows(self, table: str, cls: type) -> dict:
        """The rows of table ``table`` ("setters", "keyframers", "keyframe_deleters") that apply
        to model class ``cls``, merged along its MRO (cached per view class)."""
        key = (table, cls)
        if key not in self._row_cache:
            self._row_cache[key] = _merged(getattr(self, table), cls)
        return self._row_cache[key]

    def _setters_for(self, cls: type) -> dict[str, Setter]:
        return self._rows("setters", cls)

    def _keyframers_for(self, cls: type) -> dict[str, Keyframer]:
        return self._rows("keyframers", cls)

    def backend_object(self, item):
        """The backend counterpart of ``item`` in this view, or None if it has none."""
        return item.linked_objects.get(self)

    def add(self, item) -> None:
        found, builder = _resolve(self.builders, type(item))
        if not found:
            supported = sorted(c.__name__ for c in self.builders)
            raise TypeError(f"{type(self).__name__} cannot represent a {type(item).__name__} "
                            f"({getattr(item, 'uid', item)!r}); it supports: {supported}")
        if builder is None or self in item.linked_objects:
            return
        obj = builder(self, item)
        item.linked_objects[self] = obj
        for name, setter in self._setters_for(type(item)).items():
            setter(self, item, obj, getattr(item, name))
        for name, frames in getattr(item, "keyframes", {}).items():
            for frame in sorted(frames):
                self.on_keyframe(item, name, frame)

    def remove(self, asset) -> None:
        obj = asset.linked_objects.pop(self, None)
        if obj is not None:
            self.destroy(asset, obj)

    def destroy(self, asset, obj) -> None:
        """Delete ``obj`` from the backend (override in subclasses that can)."""

    def on_change(self, item, name: str, value) -> None:
        obj = item.linked_objects.get(self)
        if obj is None:
            return
        setter = self._setters_for(type(item)).get(name)
        if setter is not None:
            setter(self, item, obj, value)

    def on_keyframe(self, asset, name: str, frame: int) -> None:
        obj = asset.linked_objects.get(self)
        if obj is None:
            return
        keyframer = self._keyframers_for(type(asset)).get(name)
        if keyframer is not None:
            keyframer(self, asset, obj, frame)

    def on_keyframe_delete(self, asset, name: str, frame: int) -> None:
        obj = asset.linked_objects.get(self)
        if obj is None:
            return
        deleter = self._rows("keyframe_deleters", type(asset)).get(name)
        if deleter is not None:
            deleter(self, asset, obj, frame)

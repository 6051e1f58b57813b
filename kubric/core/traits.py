"""Validated, observable properties for the scene model (no third-party trait library).

A :class:`Property` is a descriptor declared on a :class:`HasProperties` subclass. Assigning to it
runs the property's converter, which either returns the canonical value or raises ``ValueError`` /
``TypeError`` naming the class, the property, the bad value and what is allowed. Every successful
assignment calls ``owner._on_property_set(name, value)``, which assets and scenes use to notify the
views linked to them.

A property whose value is itself a :class:`HasProperties` (a material's colour :class:`Texture`,
an object's material, the scene's background) records its *owner*: when the value changes, each
owner is told that its property changed too (``owner._on_dependency_changed(name)``), so views that
only know the owner (a renderer builds a Texture into the material that uses it) stay in sync.

Canonical values: vectors are **read-only float32** numpy arrays (so ``obj.position[0] = 1`` fails
instead of silently bypassing notifications), quaternions are read-only float32 WXYZ arrays, colours
are :class:`kubric.core.color.Color`.
"""

from __future__ import annotations

import weakref
from collections.abc import Callable
from typing import Any, ClassVar

import numpy as np

from kubric.core.color import get_color
from kubric.core.quaternion import Quaternion

#: A converter takes (value, owner, property name) and returns the canonical value or raises.
Converter = Callable[[Any, Any, str], Any]

_MISSING = object()


def _where(owner, name: str) -> str:
    cls = owner if isinstance(owner, type) else type(owner)
    return f"{cls.__name__}.{name}"


class UnknownPropertyError(TypeError, KeyError):
    """A keyword or property name the class does not declare.

    It is a ``TypeError`` (an unexpected keyword argument, as Python reports one) and a ``KeyError``
    (what upstream Kubric raised for an unknown trait), so code catching either keeps working.
    The message is shown as it is, not quoted as a plain ``KeyError``'s would be.
    """

    def __str__(self) -> str:
        return str(self.args[0]) if self.args else ""


class Property:
    """A declared, validated property.

    Args:
      default: the default value (converted like an assigned one) or a zero-argument callable
        returning it (for mutable defaults).
      convert: the converter (see the ``as_*`` factories below).
      doc: one line: meaning, unit, convention.
      interpolation: how keyframes of this property are interpolated: ``"linear"`` (vectors and
        scalars), ``"slerp"`` (quaternions) or ``"constant"`` (anything else).
    """

    def __init__(self, default: Any, convert: Converter, doc: str = "",
                 interpolation: str = "constant"):
        if interpolation not in ("linear", "slerp", "constant"):
            raise ValueError(f"unknown interpolation {interpolation!r}")
        self.default = default
        self.convert = convert
        self.interpolation = interpolation
        self.__doc__ = doc
        self.name = "?"

    def __set_name__(self, owner, name):
        self.name = name

    def __get__(self, obj, objtype=None):
        if obj is None:
            return self
        return obj._values[self.name]

    def __set__(self, obj, value):
        obj._set_property(self.name, value)


class HasProperties:
    """Base for everything with declared properties (assets and the scene).

    Construction is keyword-only; an unknown keyword raises ``TypeError`` naming it and the allowed
    names (an :class:`UnknownPropertyError`, which is also a ``KeyError``). Subclasses may
    override inherited defaults in ``property_defaults``.
    """

    _properties: ClassVar[dict[str, Property]] = {}
    property_defaults: ClassVar[dict[str, Any]] = {}

    def __init_subclass__(cls, **kwargs):
        super().__init_subclass__(**kwargs)
        props: dict[str, Property] = {}
        defaults: dict[str, Any] = {}
        for klass in reversed(cls.__mro__):
            for key, val in vars(klass).items():
                if isinstance(val, Property):
                    props[key] = val
            defaults.update(vars(klass).get("property_defaults", {}))
        cls._properties = props
        cls._resolved_defaults = defaults

    def _init_properties(self, kwargs: dict[str, Any]) -> None:
        unknown = sorted(set(kwargs) - set(self._properties))
        if unknown:
            raise UnknownPropertyError(
                f"{type(self).__name__} got unknown argument(s) {unknown}; "
                f"allowed: {sorted(self._properties)}")
        self._values: dict[str, Any] = {}
        self._silent = True
        try:
            for name, prop in self._properties.items():
                if name in kwargs:
                    value = kwargs[name]
                else:
                    value = self._resolved_defaults.get(name, prop.default)
                    if callable(value):  # a factory, for mutable defaults
                        value = value()
                self._values[name] = prop.convert(value, self, name)
                _track_owner(self, name, None, self._values[name])
        finally:
            self._silent = False

    def __reduce_ex__(self, protocol):
        """Assets and scenes are linked to their views (simulator, renderer) and are not values:
        pickling or copying one is refused with this message instead of a weakref error."""
        uid = getattr(self, "uid", None)
        what = f"{type(self).__name__} {uid!r}" if uid else type(self).__name__
        raise TypeError(f"{what} cannot be pickled or copied (it is linked to its scene's "
                        "views); pickle plain values instead: "
                        "asset.metadata, property values, kb.get_instance_info(scene), "
                        "kb.get_scene_metadata(scene), kb.get_camera_info(camera)")

    @classmethod
    def property_names(cls) -> tuple[str, ...]:
        """Names of all declared properties, in declaration order (base classes first)."""
        return tuple(cls._properties)

    @classmethod
    def get_property(cls, name: str) -> Property:
        try:
            return cls._properties[name]
        except KeyError:
            raise UnknownPropertyError(f"{cls.__name__} has no property {name!r}; "
                           f"allowed: {sorted(cls._properties)}") from None

    def _set_property(self, name: str, value: Any, notify: bool = True) -> None:
        prop = self.get_property(name)
        old = self._values.get(name)
        self._values[name] = prop.convert(value, self, name)
        _track_owner(self, name, old, self._values[name])
        if notify and not self._silent:
            self._on_property_set(name, self._values[name])
            self._notify_owners()

    def _on_property_set(self, name: str, value: Any) -> None:
        """Hook: called after every successful, non-silent assignment."""

    @property
    def owners(self) -> list[tuple[Any, tuple[str, ...]]]:
        """``[(owner, property names)]``: the objects whose properties currently hold this one."""
        table = self.__dict__.get("_owners")
        return [(o, tuple(sorted(n))) for o, n in table.items() if n] if table else []

    def _on_dependency_changed(self, name: str) -> None:
        """The value of property ``name`` (a HasProperties) changed inside: notify as if set."""
        self._on_property_set(name, self._values[name])
        self._notify_owners()

    def _notify_owners(self) -> None:
        owners = self.owners
        if not owners or self.__dict__.get("_notifying_owners"):
            return  # nobody holds this one, or an ownership cycle: each owner is told once
        self._notifying_owners = True
        try:
            for owner, names in owners:
                for name in names:
                    owner._on_dependency_changed(name)
        finally:
            self._notifying_owners = False


def _track_owner(owner: HasProperties, name: str, old: Any, new: Any) -> None:
    """Record that ``owner.name`` now holds ``new`` instead of ``old`` (see the module doc)."""
    if old is new:
        return
    if isinstance(old, HasProperties):
        table = old.__dict__.get("_owners")
        if table is not None and owner in table:
            table[owner].discard(name)
    if isinstance(new, HasProperties):
        table = new.__dict__.setdefault("_owners", weakref.WeakKeyDictionary())
        table.setdefault(owner, set()).add(name)


# --------------------------------------------------------------------------- converters
def _readonly(arr: np.ndarray) -> np.ndarray:
    arr.setflags(write=False)
    return arr


def as_vector(size: int = 3) -> Converter:
    """Any sequence of ``size`` finite numbers → read-only float32 array."""
    def convert(value, owner, name):
        try:
            arr = np.array(value, dtype=np.float32).reshape(-1)
        except (TypeError, ValueError):
            raise TypeError(f"{_where(owner, name)} must be {size} numbers, got {value!r}") from None
        if arr.shape != (size,) or not np.all(np.isfinite(arr)):
            raise ValueError(f"{_where(owner, name)} must be {size} finite numbers, got {value!r}")
        return _readonly(arr)
    return convert


def as_scale() -> Converter:
    """A scalar (broadcast to all axes) or 3 numbers → read-only float32 (3,) array."""
    vec = as_vector(3)

    def convert(value, owner, name):
        if np.ndim(value) == 0:
            value = (value, value, value)
        return vec(value, owner, name)
    return convert


def as_quaternion() -> Converter:
    """A WXYZ quaternion (sequence or :class:`Quaternion`) → normalised read-only float32 array."""
    def convert(value, owner, name):
        try:
            q = Quaternion(value) if not isinstance(value, Quaternion) else value
            q = q.normalised
        except (TypeError, ValueError):
            raise ValueError(f"{_where(owner, name)} must be a non-zero WXYZ quaternion "
                             f"(4 finite numbers), got {value!r}") from None
        return _readonly(np.asarray(q, dtype=np.float32))
    return convert


def as_float(low: float | None = None, high: float | None = None) -> Converter:
    """A real number, optionally within [low, high] (inclusive)."""
    def convert(value, owner, name):
        if isinstance(value, bool) or not np.isscalar(value) and np.ndim(value) != 0:
            raise TypeError(f"{_where(owner, name)} must be a number, got {value!r}")
        try:
            v = float(value)
        except (TypeError, ValueError):
            raise TypeError(f"{_where(owner, name)} must be a number, got {value!r}") from None
        if not np.isfinite(v) or (low is not None and v < low) or (high is not None and v > high):
            lo = "-inf" if low is None else f"{low:g}"
            hi = "inf" if high is None else f"{high:g}"
            raise ValueError(f"{_where(owner, name)} must be in [{lo}, {hi}], got {value!r}")
        return v
    return convert


def as_int(low: int | None = None, high: int | None = None, allow_none: bool = False) -> Converter:
    def convert(value, owner, name):
        if value is None and allow_none:
            return None
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
            raise TypeError(f"{_where(owner, name)} must be an integer, got {value!r}")
        v = int(value)
        if (low is not None and v < low) or (high is not None and v > high):
            raise ValueError(f"{_where(owner, name)} must be an integer in "
                             f"[{low if low is not None else '-inf'}, "
                             f"{high if high is not None else 'inf'}], got {value!r}")
        return v
    return convert


def as_bool() -> Converter:
    def convert(value, owner, name):
        if not isinstance(value, (bool, np.bool_)):
            raise TypeError(f"{_where(owner, name)} must be True or False, got {value!r}")
        return bool(value)
    return convert


def as_str(allow_none: bool = False) -> Converter:
    def convert(value, owner, name):
        if value is None and allow_none:
            return None
        if hasattr(value, "__fspath__"):
            value = str(value)
        if not isinstance(value, str):
            raise TypeError(f"{_where(owner, name)} must be a string, got {value!r}")
        return value
    return convert


def as_choice(choices, case_insensitive: bool = True) -> Converter:
    def convert(value, owner, name):
        if isinstance(value, str):
            for c in choices:
                if value == c or (case_insensitive and value.upper() == c.upper()):
                    return c
        raise ValueError(f"{_where(owner, name)} must be one of {list(choices)}, got {value!r}")
    return convert


def as_color() -> Converter:
    """A :class:`Color`, a name / hex string, or 3–4 floats in [0, 1] → Color."""
    def convert(value, owner, name):
        try:
            return get_color(value)
        except (TypeError, ValueError) as err:
            raise ValueError(f"{_where(owner, name)}: {err}") from None
    return convert


def as_dict() -> Converter:
    def convert(value, owner, name):
        if not isinstance(value, dict):
            raise TypeError(f"{_where(owner, name)} must be a dict, got {value!r}")
        return dict(value)
    return convert


def as_bounds() -> Converter:
    """``(lower, upper)`` 3-vectors with lower ≤ upper → read-only float32 (2, 3) array."""
    def convert(value, owner, name):
        try:
            arr = np.array(value, dtype=np.float32)
        except (TypeError, ValueError):
            arr = None
        if arr is None or arr.shape != (2, 3) or not np.all(np.isfinite(arr)):
            raise ValueError(f"{_where(owner, name)} must be ((x0, y0, z0), (x1, y1, z1)), "
                             f"got {value!r}")
        if np.any(arr[0] > arr[1]):
            raise ValueError(f"{_where(owner, name)}: lower bound {arr[0].tolist()} exceeds upper "
                             f"bound {arr[1].tolist()} (need lower ≤ upper on every axis)")
        return _readonly(arr)
    return convert


def as_instance(cls_getter: Callable[[], type], allow_none: bool = False) -> Converter:
    """An instance of the class returned by ``cls_getter`` (lazy, to allow forward references)."""
    def convert(value, owner, name):
        if value is None and allow_none:
            return None
        cls = cls_getter()
        if not isinstance(value, cls):
            raise TypeError(f"{_where(owner, name)} must be a {cls.__name__}, got {value!r}")
        return value
    return convert


# Upstream-compatible names for the common property kinds.
def Vector3D(default=(0.0, 0.0, 0.0), doc: str = "") -> Property:  # noqa: N802
    return Property(default, as_vector(3), doc, interpolation="linear")


def Scale(default=(1.0, 1.0, 1.0), doc: str = "") -> Property:  # noqa: N802
    return Property(default, as_scale(), doc, interpolation="linear")


def QuaternionProperty(default=(1.0, 0.0, 0.0, 0.0), doc: str = "") -> Property:  # noqa: N802
    return Property(default, as_quaternion(), doc, interpolation="slerp")


def RGBA(default="white", doc: str = "") -> Property:  # noqa: N802
    return Property(default, as_color(), doc, interpolation="linear")


def Float(default: float = 0.0, low=None, high=None, doc: str = "") -> Property:  # noqa: N802
    return Property(default, as_float(low, high), doc, interpolation="linear")


__all__ = [
    "UnknownPropertyError", "Property", "HasProperties", "Converter", "as_vector", "as_scale",
    "as_quaternion", "as_float", "as_int", "as_bool", "as_str", "as_choice", "as_color", "as_dict",
    "as_bounds", "as_instance", "Vector3D", "Scale", "QuaternionProperty", "RGBA", "Float",
]

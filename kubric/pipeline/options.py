"""Declared, typed recipe options (defaults, help, validation) and ``--set key=value`` parsing.

An :class:`Option` is declared as a class attribute of a recipe::

    class MyRecipe(Recipe, name="mine"):
        resolution = Option((256, 256), "(width, height) in pixels", type=resolution)
        samples = Option(64, "Cycles samples per pixel", low=1)

Values arrive either as Python objects (API) or as strings (``--set samples=16``); both go through
the same conversion and checks. Every failure raises :class:`OptionError` whose message is one
line naming the recipe, the option, the bad value and what is allowed.

Bounds: ``low``/``high`` are hard limits. ``limit`` is a *default* upper bound on sizes that make a
scene huge or slow (resolution 8192, frame_end 10000, ...): exceeding it is refused unless the
environment variable ``KUBRIC_ALLOW_LARGE=1`` is set (it is inherited by the runner's workers).
Every number must be finite: NaN and ±inf are refused for every option.
"""

from __future__ import annotations

import math
import os
import pathlib
from collections.abc import Callable, Mapping, Sequence
from typing import Any

from kubric.core.resolution import ALLOWED as RESOLUTIONS_ALLOWED
from kubric.core.resolution import parse_resolution
from kubric.errors import UsageError

#: environment variable lifting every option's default upper bound (``limit``)
ALLOW_LARGE_ENV = "KUBRIC_ALLOW_LARGE"

_TRUE = {"1", "true", "yes", "on"}
_FALSE = {"0", "false", "no", "off"}


class OptionError(UsageError, ValueError):
    """A bad option value or name (one-line message)."""


def _to_bool(value):
    if isinstance(value, bool):
        return value
    if isinstance(value, str) and value.strip().lower() in _TRUE | _FALSE:
        return value.strip().lower() in _TRUE
    if isinstance(value, int) and value in (0, 1):
        return bool(value)
    raise ValueError(f"expected a boolean ({'/'.join(sorted(_TRUE | _FALSE))})")


def _to_int(value):
    if isinstance(value, bool):
        raise ValueError("expected an integer")
    if isinstance(value, str):
        return int(value.strip())
    if isinstance(value, float) and not value.is_integer():
        raise ValueError("expected an integer")
    return int(value)


def _to_float(value):
    if isinstance(value, bool):
        raise ValueError("expected a number")
    number = float(value.strip() if isinstance(value, str) else value)
    if not math.isfinite(number):
        raise ValueError("expected a finite number")
    return number


def allow_large() -> bool:
    """True when ``KUBRIC_ALLOW_LARGE`` lifts the default upper bounds (``Option(limit=...)``)."""
    return os.environ.get(ALLOW_LARGE_ENV, "").strip().lower() in _TRUE


def _to_str(value):
    if not isinstance(value, str):
        raise ValueError("expected a string")
    return value


def _to_path(value):
    if not isinstance(value, (str, pathlib.Path)) or not str(value):
        raise ValueError("expected a path")
    return pathlib.Path(value).expanduser()


_CONVERTERS: dict[Any, Callable[[Any], Any]] = {
    bool: _to_bool, int: _to_int, float: _to_float, str: _to_str, pathlib.Path: _to_path,
}


def resolution(value) -> tuple[int, int]:
    """Converter for (width, height): every spelling of
    :func:`kubric.core.resolution.parse_resolution` (``256``, ``"320x240"``, ``"320,240"``, ...)."""
    try:
        return parse_resolution(value)
    except ValueError:  # Option.convert names the option, the value and what is allowed
        raise ValueError("not a resolution") from None


resolution.allowed = RESOLUTIONS_ALLOWED
resolution.limit = 8192  # pixels per side (KUBRIC_ALLOW_LARGE=1 lifts it)


def float_range(value) -> tuple[float, float]:
    """Converter for a ``(low, high)`` pair with low ≤ high: ``"0.7,1.4"`` or ``(0.7, 1.4)``."""
    if isinstance(value, str):
        value = value.replace(":", ",").split(",")
    try:
        low, high = (float(v) for v in value)
    except (TypeError, ValueError):
        raise ValueError("expected two numbers low,high") from None
    if not (math.isfinite(low) and math.isfinite(high)):
        raise ValueError("expected two finite numbers low,high")
    if low > high:
        raise ValueError("expected low ≤ high")
    return low, high


float_range.allowed = "two numbers low,high with low ≤ high, e.g. 0.7,1.4,"


class Option:
    """One declared option.

    Args:
      default: the value when not given (None allowed with ``nullable=True``).
      help: one line: meaning and unit.
      type: ``bool``, ``int``, ``float``, ``str``, ``pathlib.Path`` or a converter
        ``value -> value`` raising ValueError; default: the type of ``default``.
      choices: allowed values (after conversion).
      low, high: inclusive hard bounds for numbers (for tuples: every element).
      limit: inclusive default upper bound (for tuples: every element) that the environment
        variable ``KUBRIC_ALLOW_LARGE=1`` lifts; default: the converter's ``limit`` attribute
        (e.g. :func:`resolution`: 8192 pixels).
      must_exist: for paths: the path must exist when the recipe is built.
      nullable: accept None (``--set key=none``).
    """

    def __init__(self, default: Any, help: str = "", *, type: Any = None,
                 choices: Sequence | None = None, low: float | None = None,
                 high: float | None = None, limit: float | None = None,
                 must_exist: bool = False, nullable: bool = False):
        if type is None:
            if default is None:
                raise TypeError("Option(default=None) needs an explicit type=")
            type = builtins_type(default)
        self.default = default
        self.help = help
        self.type = type
        self.convert_value = _CONVERTERS.get(type, type)
        self.choices = tuple(choices) if choices is not None else None
        self.low, self.high = low, high
        self.limit = limit if limit is not None else getattr(type, "limit", None)
        self.must_exist = must_exist
        self.nullable = nullable or default is None
        self.name = "?"

    def __set_name__(self, owner, name):
        self.name = name

    def __get__(self, obj, objtype=None):
        if obj is None:
            return self
        return obj.values[self.name]

    @property
    def type_name(self) -> str:
        return getattr(self.type, "__name__", str(self.type))

    def allowed(self) -> str:
        """Human description of the allowed values."""
        parts = [getattr(self.type, "allowed", self.type_name)]
        if self.choices is not None:
            parts = ["one of " + ", ".join(map(str, self.choices))]
        if self.low is not None:
            parts.append(f"≥ {self.low}")
        if self.limit is not None and not allow_large():
            beyond = f", then ≤ {self.high}" if self.high is not None else ""
            parts.append(f"≤ {self.limit} (unless {ALLOW_LARGE_ENV}=1{beyond})")
        elif self.high is not None:
            parts.append(f"≤ {self.high}")
        if self.must_exist:
            parts.append("an existing path")
        if self.nullable:
            parts.append("or none")
        return " ".join(parts)

    def convert(self, value, owner: str = "recipe"):
        """Converted, checked value; raises OptionError (one line)."""
        shown = repr(value)
        if len(shown) > 80:  # a pasted file, a runaway number: the start names it well enough
            shown = shown[:60] + f"... ({len(shown)} characters)"
        where = f"{owner}: option {self.name}={shown}"
        if value is None or (isinstance(value, str) and value.strip().lower() == "none"
                             and self.nullable):
            if self.nullable:
                return None
            raise OptionError(f"{where}: a value is required ({self.allowed()})")
        try:
            v = self.convert_value(value)
        except (TypeError, ValueError) as err:
            raise OptionError(f"{where}: {err} (allowed: {self.allowed()})") from None
        if self.choices is not None and v not in self.choices:
            raise OptionError(f"{where}: not allowed (allowed: {self.allowed()})")
        numbers = v if isinstance(v, tuple) else (v,)
        for n in numbers:
            if isinstance(n, (int, float)) and not isinstance(n, bool):
                if isinstance(n, float) and not math.isfinite(n):
                    raise OptionError(f"{where}: not a finite number (allowed: {self.allowed()})")
                if (self.low is not None and n < self.low) or \
                        (self.high is not None and n > self.high):
                    raise OptionError(f"{where}: out of range (allowed: {self.allowed()})")
                if self.limit is not None and n > self.limit and not allow_large():
                    raise OptionError(f"{where}: above the default bound {self.limit} (set "
                                      f"{ALLOW_LARGE_ENV}=1 to allow; allowed: {self.allowed()})")
        if self.must_exist:
            try:
                exists = pathlib.Path(v).exists()
            except (OSError, ValueError) as err:  # a name too long, a NUL byte, ...
                raise OptionError(f"{where}: not a usable path ({_one_line(err)})") from None
            if not exists:
                raise OptionError(f"{where}: path does not exist")
        return v


def _one_line(err: BaseException) -> str:
    return " ".join(str(err).split())[:200]


def builtins_type(default):
    if isinstance(default, bool):
        return bool
    if isinstance(default, pathlib.Path):
        return pathlib.Path
    for t in (int, float, str):
        if isinstance(default, t):
            return t
    raise TypeError(f"Option default {default!r}: give type= explicitly")


def parse_assignments(pairs: Sequence[str]) -> dict[str, str]:
    """``["a=1", "b=x"]`` → ``{"a": "1", "b": "x"}``; raises OptionError on a malformed pair."""
    out: dict[str, str] = {}
    for pair in pairs or ():
        key, sep, value = pair.partition("=")
        if not sep or not key.strip():
            raise OptionError(f"--set expects key=value, got {pair!r}")
        out[key.strip()] = value
    return out


def convert_all(options: Mapping[str, Option], given: Mapping[str, Any],
                owner: str) -> dict[str, Any]:
    """All option values: ``given`` converted and checked, defaults for the rest. An unknown key
    raises OptionError listing the known ones."""
    unknown = sorted(set(given) - set(options))
    if unknown:
        raise OptionError(f"{owner}: unknown option {unknown[0]!r} "
                          f"(options: {', '.join(sorted(options)) or 'none'})")
    values = {}
    for name, opt in options.items():
        values[name] = opt.convert(given[name], owner) if name in given else \
            (opt.default if opt.default is None else opt.convert(opt.default, owner))
    return values

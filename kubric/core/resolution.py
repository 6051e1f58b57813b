"""The one parser of image resolutions, shared by ``Scene.resolution``, ``Scene.from_flags``,
``kb.ArgumentParser --resolution``, ``kb.setup`` and recipe options (``--set resolution=…``).

Accepted spellings, all giving ``(width, height)``:

* one positive integer ``N`` (``256``, ``numpy.int64(256)``, ``256.0``) or the string ``"256"`` → (N, N);
* a string ``"WxH"``, ``"WXH"``, ``"W×H"`` or ``"W,H"`` (spaces around the numbers allowed);
* a pair ``(W, H)`` / ``[W, H]`` / a 2-element array of positive integers (integral floats allowed).

Anything else — zero or negative sizes, fractions, booleans, ``"12x"``, ``"1x2x3"``, ``"big"`` —
raises ``ValueError`` with one line naming the value and these spellings.
"""

from __future__ import annotations

import math
import numbers
import re

#: the spellings, as they appear in every error message.
ALLOWED = "N or WxH with positive integers (e.g. 256, 320x240, 320,240 or (320, 240))"

_SEPARATOR = re.compile(r"\s*[xX×,]\s*")


def _size(v) -> int | None:
    """``v`` as a positive int, or None when it is not one."""
    if isinstance(v, bool) or not isinstance(v, numbers.Real):
        return None
    f = float(v)
    if not math.isfinite(f) or not f.is_integer() or f < 1:
        return None
    return int(f)


def parse_resolution(value, what: str = "resolution") -> tuple[int, int]:
    """``value`` (see module doc) as ``(width, height)``; ``ValueError`` naming ``what``, the
    value and the allowed spellings otherwise."""
    if isinstance(value, str):
        text = value.strip()
        parts = _SEPARATOR.split(text) if text else []
        if len(parts) == 1:
            parts *= 2
        sizes = [int(p) if p.isdigit() and p.isascii() else None for p in parts]
    elif isinstance(value, numbers.Real):
        sizes = [_size(value)] * 2
    else:
        try:
            items = list(value)
        except TypeError:
            items = []
        sizes = [_size(v) for v in items]
    if len(sizes) != 2 or any(s is None or s < 1 for s in sizes):
        raise ValueError(f"{what} must be {ALLOWED}, got {value!r}")
    return sizes[0], sizes[1]


__all__ = ["ALLOWED", "parse_resolution"]

"""The rng policy every sampling function follows (:mod:`kubric.randomness`,
``kubric.assets.utils.get_clevr_lights``): what ``rng=None`` means, and the worker's rng.

Upstream scripts sometimes omit ``rng``. For them, ``rng=None`` means, in this order:

1. *the worker's rng*: the :class:`WorkerRandomState` that :func:`kubric.utils.setup` returned,
   seeded from ``--seed`` (and recorded in the metadata), for as long as the caller holds it —
   this module keeps only a weak reference, so the binding ends with its owner (a test that called
   ``kb.setup`` leaves nothing behind once it returns; nothing needs resetting);
2. otherwise, only in the functions whose upstream signature had an unseeded default generator
   (:data:`UPSTREAM_DEFAULTED`), one process-wide ``numpy.random.RandomState()`` seeded from OS
   entropy, as upstream had. Its results differ on every run: **not reproducible**. The first
   use warns (:class:`UnseededRandomnessWarning`, once per function);
3. otherwise a ``TypeError``.

Inside :func:`explicit_rng_only` (every recipe run) ``rng=None`` and :func:`default_rng` raise
``RuntimeError`` naming the function. The public names are re-exported by
:mod:`kubric.randomness` (upstream's home of them); this module sits in the scene model's layer so
that the asset runtime may follow the policy without importing the samplers.
"""

from __future__ import annotations

import contextlib
import threading
import warnings
import weakref
from collections.abc import Iterator

import numpy as np


class WorkerRandomState(np.random.RandomState):
    """The rng :func:`kubric.utils.setup` returns: a ``numpy.random.RandomState`` (same stream
    for the same seed) that also carries the run's ``output_dir`` (where ``kb.done`` marks the run
    complete). While it is alive and bound, sampling functions called with ``rng=None`` use it."""

    output_dir = None


_worker_ref: weakref.ref | None = None  # weak: the binding lives exactly as long as its owner


def bind_worker_rng(rng: WorkerRandomState) -> None:
    """Make ``rng`` the one used where a caller passes ``rng=None`` (called by ``kb.setup``),
    for as long as something else holds ``rng``."""
    global _worker_ref
    if not isinstance(rng, WorkerRandomState):
        raise TypeError(f"bind_worker_rng needs a kubric.randomness.WorkerRandomState, got {rng!r}")
    _worker_ref = weakref.ref(rng)


def worker_rng() -> WorkerRandomState | None:
    """The bound worker rng if its owner still holds it, else None."""
    return _worker_ref() if _worker_ref is not None else None


#: the public functions whose upstream signature defaulted ``rng`` to an unseeded generator
UPSTREAM_DEFAULTED = frozenset({
    "random_hue_color", "random_rotation", "resample_while", "move_until_no_overlap",
    "sample_color", "sample_sizes", "sample_point_in_half_sphere_shell",
    "kb.assets.utils.get_clevr_lights",
})


class UnseededRandomnessWarning(UserWarning):
    """A sampling function ran on the unseeded generator: its results are not reproducible."""


_unseeded: np.random.RandomState | None = None
_warned: set[str] = set()
_forbidden = threading.local()  # .reasons: list of active explicit_rng_only() reasons


@contextlib.contextmanager
def explicit_rng_only(reason: str) -> Iterator[None]:
    """Inside this block (in this thread) every sampling function needs an explicit ``rng``:
    ``rng=None`` (whether or not a worker rng is bound) and :func:`default_rng` raise
    ``RuntimeError`` naming the function and ``reason``. Recipe runs use it."""
    reasons = _forbidden.__dict__.setdefault("reasons", [])
    reasons.append(str(reason))
    try:
        yield
    finally:
        reasons.pop()


def _check_unseeded_allowed(where: str) -> None:
    reasons = getattr(_forbidden, "reasons", None)
    if reasons:
        raise RuntimeError(f"{where} was called without an explicit rng inside {reasons[-1]}; "
                           "pass rng= (results must follow the scene's seed)")


def default_rng() -> np.random.RandomState:
    """A new ``numpy.random.RandomState()`` seeded from OS entropy (upstream's ``default_rng``):
    **not reproducible**; pass a seeded rng wherever results should follow a seed."""
    _check_unseeded_allowed("kubric.randomness.default_rng()")
    return np.random.RandomState()


def _unseeded_rng(where: str) -> np.random.RandomState:
    global _unseeded
    _check_unseeded_allowed(where)
    if where not in _warned:
        _warned.add(where)
        warnings.warn(f"{where} called without rng= and no kb.setup() rng is held: using an "
                      "unseeded generator (as upstream Kubric did); results are not "
                      "reproducible", UnseededRandomnessWarning, stacklevel=4)
    if _unseeded is None:
        _unseeded = np.random.RandomState()
    return _unseeded


def require_rng(rng, where: str):
    if rng is None:
        _check_unseeded_allowed(where)
        bound = worker_rng()
        if bound is not None:
            return bound
        if where in UPSTREAM_DEFAULTED:
            return _unseeded_rng(where)
        raise TypeError(f"{where} needs rng=numpy.random.RandomState(seed) (or call "
                        "kb.setup(flags) first and keep the rng it returns, which is seeded "
                        "from --seed)")
    if not isinstance(rng, (np.random.RandomState, np.random.Generator)):
        raise TypeError(f"{where} needs rng=numpy.random.RandomState(...) or "
                        f"numpy.random.default_rng(...), got {rng!r}")
    return rng

"""Random scene sampling. Every function takes an ``rng`` (``numpy.random.RandomState`` or
``numpy.random.Generator``); pass one and one seed fixes a scene.

Upstream scripts sometimes omit ``rng``. For them, ``rng=None`` means, in this order (the policy
lives in :mod:`kubric.core.rng`, re-exported here):

1. *the worker's rng*: the :class:`WorkerRandomState` that :func:`kubric.utils.setup` returned,
   seeded from ``--seed`` (and recorded in the metadata), for as long as the caller holds it —
   this module keeps only a weak reference, so the binding ends with its owner (a test that called
   ``kb.setup`` leaves nothing behind once it returns; nothing needs resetting);
2. otherwise, only in the functions whose upstream signature had an unseeded default generator
   (:data:`UPSTREAM_DEFAULTED`: ``random_hue_color``, ``random_rotation``, ``resample_while``,
   ``move_until_no_overlap``, ``sample_color``, ``sample_sizes``,
   ``sample_point_in_half_sphere_shell`` and ``kb.assets.utils.get_clevr_lights``), one
   process-wide ``numpy.random.RandomState()`` seeded from OS entropy, as upstream had. Its
   results differ on every run: **not reproducible**. The first use warns
   (:class:`UnseededRandomnessWarning`, once per function);
3. otherwise (functions upstream never defaulted, e.g. ``random_clevr_color``) a ``TypeError``.

:func:`default_rng` is upstream's helper of that name: a fresh unseeded ``RandomState``.

Recipes pass ``rng`` explicitly and never use the unseeded generator:
:func:`kubric.pipeline.worker.run_scene` runs every recipe inside :func:`explicit_rng_only`, where
``rng=None`` (even with a worker rng bound) and :func:`default_rng` raise ``RuntimeError`` naming
the function.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from kubric.assets import clevr
from kubric.core.color import Color
from kubric.core.objects import PhysicalObject
from kubric.core.quaternion import Quaternion
from kubric.core.rng import (  # noqa: F401  (the rng policy's public names, upstream's home)
    UPSTREAM_DEFAULTED,
    UnseededRandomnessWarning,
    WorkerRandomState,
    bind_worker_rng,
    default_rng,
    explicit_rng_only,
    require_rng,
    worker_rng,
)
from kubric.errors import KubricError


def _uniform(rng, low=0.0, high=1.0, size=None):
    return rng.uniform(low, high, size)


def _choice_index(rng, n: int) -> int:
    if isinstance(rng, np.random.Generator):
        return int(rng.integers(n))
    return int(rng.randint(n))


def random_hue_color(saturation: float = 1.0, value: float = 1.0, rng=None) -> Color:
    """A colour of uniformly random hue with the given HSV saturation and value."""
    rng = require_rng(rng, "random_hue_color")
    return Color.from_hsv(float(_uniform(rng)), saturation, value)


def random_clevr_color(rng=None) -> tuple[str, Color]:
    """(name, Color) of a uniformly chosen CLEVR colour (:data:`kubric.assets.clevr.COLORS`)."""
    rng = require_rng(rng, "random_clevr_color")
    names = sorted(clevr.COLORS)
    name = names[_choice_index(rng, len(names))]
    return name, clevr.COLORS[name]


def random_rotation(axis: str | Sequence[float] | None = None, rng=None) -> tuple[float, ...]:
    """A uniformly random rotation (WXYZ tuple): about ``axis`` ("X", "Y", "Z" or a vector) by a
    uniform angle, or uniform over SO(3) when ``axis`` is None."""
    rng = require_rng(rng, "random_rotation")
    if axis is None:
        # Shoemake's method: uniform over SO(3).
        u1, u2, u3 = (float(v) for v in _uniform(rng, size=3))
        q = (np.sqrt(u1) * np.cos(2 * np.pi * u3), np.sqrt(1 - u1) * np.sin(2 * np.pi * u2),
             np.sqrt(1 - u1) * np.cos(2 * np.pi * u2), np.sqrt(u1) * np.sin(2 * np.pi * u3))
        return tuple(float(v) for v in q)
    angle = float(_uniform(rng, 0.0, 2 * np.pi))
    return tuple(Quaternion(axis=axis, angle=angle))


def rotation_sampler(axis=None) -> Callable[[PhysicalObject, Any], None]:
    """A sampler ``(obj, rng) → None`` that sets a random rotation (see :func:`random_rotation`)."""
    def sample(obj, rng):
        obj.quaternion = random_rotation(axis=axis, rng=rng)
    return sample


class DoesNotFitError(KubricError, ValueError):
    """The object's rotated bounding box is larger than the sampling region on some axis."""


def _region(region) -> np.ndarray:
    arr = np.asarray(region, dtype=np.float64)
    if arr.shape != (2, 3) or np.any(arr[0] > arr[1]):
        raise ValueError(f"a region must be [[x0, y0, z0], [x1, y1, z1]] with lower ≤ upper, "
                         f"got {region!r}")
    return arr


def position_sampler(region) -> Callable[[PhysicalObject, Any], None]:
    """A sampler that moves the object so that its (rotated, scaled) axis-aligned bounding box lies
    inside ``region`` = [[x0, y0, z0], [x1, y1, z1]] (uniformly among such positions)."""
    region = _region(region)

    def sample(obj, rng):
        box = obj.aabbox - np.asarray(obj.position, dtype=np.float64)
        low, high = region[0] - box[0], region[1] - box[1]
        if np.any(low > high):
            raise DoesNotFitError(f"{obj.uid} (extent {(box[1] - box[0]).round(3).tolist()}) "
                                  f"does not fit in region {region.tolist()}")
        obj.position = _uniform(rng, low, high)
    return sample


def bottom_sampler(region) -> Callable[[PhysicalObject, Any], None]:
    """Like :func:`position_sampler` but the object's lowest point rests on the region's floor."""
    region = _region(region)

    def sample(obj, rng):
        box = obj.aabbox - np.asarray(obj.position, dtype=np.float64)
        low, high = region[0] - box[0], region[1] - box[1]
        if np.any(low[:2] > high[:2]):
            raise DoesNotFitError(f"{obj.uid} does not fit in region {region.tolist()}")
        xy = _uniform(rng, low[:2], high[:2])
        obj.position = (xy[0], xy[1], region[0, 2] - box[0, 2])
    return sample


def resample_while(asset, samplers: Sequence[Callable], condition: Callable[[Any], bool],
                   max_trials: int = 100, rng=None) -> int:
    """Apply ``samplers`` (each ``(asset, rng)``) until ``condition(asset)`` is False.

    A trial in which a sampler raises :class:`DoesNotFitError` (e.g. a rotation whose bounding box
    is larger than the region) counts as rejected. Returns the number of trials used; raises
    ``RuntimeError`` naming the asset after ``max_trials``. If no trial succeeded, the asset keeps
    its last sampled pose.
    """
    rng = require_rng(rng, "resample_while")
    if max_trials < 1:
        raise ValueError(f"max_trials must be ≥ 1, got {max_trials}")
    too_big = 0
    for trial in range(1, max_trials + 1):
        try:
            for sampler in samplers:
                sampler(asset, rng)
        except DoesNotFitError:
            too_big += 1
            continue
        if not condition(asset):
            return trial
    detail = f"; {too_big} of them did not fit in the region" if too_big else ""
    raise RuntimeError(f"{asset.uid}: no valid sample after {max_trials} trials{detail} "
                       f"(enlarge the region or allow more trials)")


def move_until_no_overlap(asset, simulator, spawn_region=((-1, -1, -1), (1, 1, 1)),
                          max_trials: int = 100, rng=None) -> int:
    """Give ``asset`` a random rotation and a position whose bounding box lies inside
    ``spawn_region`` until it overlaps nothing in ``simulator`` (which must offer
    ``check_overlap(asset)``). Rotations too large for the region are rejected trials. Returns the
    trials used; ``RuntimeError`` naming the asset after ``max_trials``."""
    rng = require_rng(rng, "move_until_no_overlap")
    return resample_while(asset, samplers=[rotation_sampler(), position_sampler(spawn_region)],
                          condition=simulator.check_overlap, max_trials=max_trials, rng=rng)


def sample_point_in_half_sphere_shell(inner_radius: float, outer_radius: float,
                                      offset: float = 0.0, rng=None) -> np.ndarray:
    """A point (3,) uniformly distributed in the upper half of a spherical shell
    (inner_radius ≤ |p| ≤ outer_radius, z ≥ offset)."""
    rng = require_rng(rng, "sample_point_in_half_sphere_shell")
    if not 0 <= inner_radius <= outer_radius:
        raise ValueError(f"need 0 ≤ inner_radius ≤ outer_radius, got {inner_radius}, "
                         f"{outer_radius}")
    if offset >= outer_radius:
        raise ValueError(f"offset {offset} leaves no room below outer_radius {outer_radius}")
    while True:
        v = np.asarray(_uniform(rng, (-outer_radius, -outer_radius, offset),
                                (outer_radius, outer_radius, outer_radius)), dtype=np.float64)
        if inner_radius <= np.linalg.norm(v) <= outer_radius:
            return v


def sample_color(strategy: str, rng=None) -> tuple[str | None, Color]:
    """(label, colour) by strategy: ``"clevr"`` (a CLEVR colour and its name), ``"uniform_hue"``
    (random hue, label None) or ``"gray"``."""
    rng = require_rng(rng, "sample_color")
    if strategy == "clevr":
        return random_clevr_color(rng=rng)
    if strategy == "uniform_hue":
        return None, random_hue_color(rng=rng)
    if strategy == "gray":
        return "gray", Color.from_name("gray")
    raise ValueError(f"unknown colour strategy {strategy!r}; allowed: clevr, uniform_hue, gray")


def sample_sizes(strategy: str, rng=None) -> tuple[str | None, float]:
    """(label, scale) by strategy: ``"clevr"`` (:data:`kubric.assets.clevr.SIZES`: small 0.7 /
    large 1.4), ``"uniform"`` (U(small, large), label None) or ``"const"`` (1)."""
    rng = require_rng(rng, "sample_sizes")
    if strategy == "clevr":
        labels = list(clevr.SIZES)
        label = labels[_choice_index(rng, len(labels))]
        return label, clevr.SIZES[label]
    if strategy == "uniform":
        return None, float(_uniform(rng, clevr.SIZES["small"], clevr.SIZES["large"]))
    if strategy == "const":
        return None, 1.0
    raise ValueError(f"unknown size strategy {strategy!r}; allowed: clevr, uniform, const")

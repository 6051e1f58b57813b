"""move_until_no_overlap + PyBullet.check_overlap, checked with independent geometry."""

import itertools

import numpy as np
import pytest

import kubric as kb
from kubric.simulator import PyBullet

REGION = ((-1.5, -1.5, 0.0), (1.5, 1.5, 1.5))


def _box(obj):
    """(centre (3,), axes (3, 3) rows = unit axes, half extents (3,)) of a Cube."""
    return (np.asarray(obj.position, np.float64), obj.rotation_matrix.T,
            np.asarray(obj.scale, np.float64))


def _box_box_separated(a, b, tol):
    """Separating-axis test for two oriented boxes (15 candidate axes)."""
    (ca, axa, ha), (cb, axb, hb) = a, b
    axes = list(axa) + list(axb)
    for u, v in itertools.product(axa, axb):
        c = np.cross(u, v)
        if np.linalg.norm(c) > 1e-9:
            axes.append(c / np.linalg.norm(c))
    d = cb - ca
    for axis in axes:
        ra = np.sum(ha * np.abs(axa @ axis))
        rb = np.sum(hb * np.abs(axb @ axis))
        if abs(d @ axis) >= ra + rb - tol:
            return True
    return False


def _sphere_box_separated(centre, radius, box, tol):
    c, axes, h = box
    local = axes @ (centre - c)
    closest = np.clip(local, -h, h)
    return np.linalg.norm(local - closest) >= radius - tol


def penetrates(a, b, tol=1e-4):
    """True when a and b (Cube or Sphere) overlap by more than ``tol`` metres."""
    if isinstance(a, kb.Sphere) and isinstance(b, kb.Sphere):
        dist = np.linalg.norm(np.asarray(a.position, float) - np.asarray(b.position, float))
        return dist < a.scale[0] + b.scale[0] - tol
    if isinstance(a, kb.Cube) and isinstance(b, kb.Cube):
        return not _box_box_separated(_box(a), _box(b), tol)
    sphere, cube = (a, b) if isinstance(a, kb.Sphere) else (b, a)
    return not _sphere_box_separated(np.asarray(sphere.position, float), float(sphere.scale[0]),
                                     _box(cube), tol)


def test_independent_checker_sees_known_cases():
    c1, c2 = kb.Cube(scale=0.5), kb.Cube(scale=0.5, position=(0.9, 0, 0))
    assert penetrates(c1, c2)
    c2.position = (1.1, 0, 0)
    assert not penetrates(c1, c2)
    c2.quaternion = kb.Quaternion(axis="Z", angle=np.pi / 4)  # corner reaches x = 1.1 - 0.707
    assert penetrates(c1, c2)
    s = kb.Sphere(scale=0.3, position=(0.75, 0.0, 0.0))
    assert penetrates(c1, s) and not penetrates(s, kb.Sphere(scale=0.3, position=(0, 0.7, 0)))


def test_check_overlap_matches_geometry():
    scene = kb.Scene()
    a = kb.Cube(scale=0.5)
    b = kb.Sphere(scale=0.5, position=(0.9, 0.0, 0.0))
    scene.add([a, b])
    sim = PyBullet(scene)
    assert sim.check_overlap(a) and sim.check_overlap(b)
    b.position = (1.01, 0.0, 0.0)  # follows the model without a run
    assert not sim.check_overlap(a)
    a.quaternion = kb.Quaternion(axis="Y", angle=np.pi / 4)  # an edge now reaches x = 0.707
    assert sim.check_overlap(a) and sim.check_overlap(b)
    rng = np.random.RandomState(3)
    results = []
    for _ in range(20):
        a.quaternion = kb.random_rotation(rng=rng)
        results.append(sim.check_overlap(a))
        assert results[-1] == penetrates(a, b, tol=0.0)
    assert any(results) and not all(results)
    with pytest.raises(ValueError, match="Camera"):
        cam = kb.PerspectiveCamera()
        scene.add(cam)
        sim.check_overlap(cam)
    sim.close()


@pytest.mark.parametrize("seed", [0, 1])
def test_move_until_no_overlap_places_ten_objects(seed):
    rng = np.random.RandomState(seed)
    scene = kb.Scene()
    floor = kb.Cube(scale=(3, 3, 0.1), position=(0, 0, -0.1), static=True)
    scene.add(floor)
    sim = PyBullet(scene)
    objects = []
    for i in range(10):
        size = float(rng.uniform(0.15, 0.3))
        obj = kb.Cube(scale=size) if i % 2 else kb.Sphere(scale=size)
        scene.add(obj)
        trials = kb.move_until_no_overlap(obj, sim, spawn_region=REGION, max_trials=200, rng=rng)
        assert 1 <= trials <= 200
        objects.append(obj)
    for obj in objects:
        lo, hi = obj.aabbox
        assert np.all(lo >= np.array(REGION[0]) - 1e-5) and np.all(hi <= np.array(REGION[1]) + 1e-5)
        assert not sim.check_overlap(obj)
    for a, b in itertools.combinations(objects + [floor], 2):
        assert not penetrates(a, b), (a, b, a.position, b.position)
    sim.close()


def test_move_until_no_overlap_gives_up_with_clear_error():
    rng = np.random.RandomState(0)
    scene = kb.Scene()
    big = kb.Cube(scale=2.0, static=True)
    small = kb.Sphere(scale=0.3)
    scene.add([big, small])
    sim = PyBullet(scene)
    with pytest.raises(RuntimeError, match=r"Sphere.*5 trials"):
        kb.move_until_no_overlap(small, sim, spawn_region=((-1, -1, -1), (1, 1, 1)),
                                 max_trials=5, rng=rng)
    sim.close()


def test_move_until_no_overlap_is_seeded():
    def place(seed):
        scene = kb.Scene()
        objs = [kb.Cube(scale=0.3) for _ in range(4)]
        scene.add(objs)
        sim = PyBullet(scene)
        rng = np.random.default_rng(seed)
        for obj in objs:
            kb.move_until_no_overlap(obj, sim, spawn_region=REGION, max_trials=100, rng=rng)
        out = np.array([np.concatenate([o.position, o.quaternion]) for o in objs])
        sim.close()
        return out
    np.testing.assert_array_equal(place(7), place(7))
    assert not np.array_equal(place(7), place(8))

"""MOVi-A / MOVi-B placement with unit-sized KuBasic shapes (no rendering).

Upstream's KuBasic shapes fit a 1 m cube, so MOVi's scales give CLEVR's object sizes and every
object of a scene finds a free place: 50 seeds of each recipe drop none.
"""

import numpy as np
import pytest

import kubric as kb
from kubric.assets import clevr
from kubric.pipeline import get_recipe
from kubric.recipes.movi_base import DYNAMIC_SPAWN_REGION


def _populated(recipe, sources, seed):
    scene = recipe.make_scene()
    simulator = kb.simulator.PyBullet(scene)
    try:
        recipe.populate(scene, simulator, np.random.RandomState(seed), sources)
        objects = [a for a in scene.foreground_assets if isinstance(a, kb.PhysicalObject)]
        return scene, objects
    finally:
        simulator.close()


@pytest.mark.parametrize("name", ["movi_a", "movi_b"])
def test_fifty_seeds_place_every_object(name):
    recipe = get_recipe(name)()
    sources = recipe.open_sources()
    low, high = (np.asarray(c) for c in DYNAMIC_SPAWN_REGION)
    counts = []
    for seed in range(50):
        scene, objects = _populated(recipe, sources, seed)
        assert scene.metadata["dropped_objects"] == 0, seed
        assert recipe.min_num_objects <= len(objects) <= recipe.max_num_objects, seed
        for obj in objects:  # inside the spawn region (rotated bounding box included)
            box = np.asarray(obj.aabbox)
            assert np.all(box[0] >= low - 1e-6) and np.all(box[1] <= high + 1e-6), (seed, obj)
        counts.append(len(objects))
    assert max(counts) == recipe.max_num_objects  # crowded scenes were among them


def test_movi_a_objects_have_clevr_sizes():
    """A KuBasic shape of scale s spans s metres: CLEVR's small (0.7 m) and large (1.4 m)."""
    recipe = get_recipe("movi_a")()
    sources = recipe.open_sources()
    seen = set()
    for seed in range(5):
        _, objects = _populated(recipe, sources, seed)
        for obj in objects:
            label, size = obj.metadata["size_label"], obj.metadata["size"]
            assert size == clevr.SIZES[label]
            # the unrotated model bounds times the scale: the object's extent in metres
            extent = np.ptp(np.asarray(obj.bounds), axis=0) * np.asarray(obj.scale)
            assert extent.max() == pytest.approx(size, rel=1e-6), (seed, obj.metadata["shape"])
            if obj.metadata["shape"] == "cube":
                np.testing.assert_allclose(extent, size, rtol=1e-6)
            # mass rule 2.7·s³ (metal) / 1.1·s³ (rubber) of a unit-volume cube
            if obj.metadata["shape"] == "cube":
                density = {"metal": 2.7, "rubber": 1.1}[obj.metadata["material"]]
                assert obj.mass == pytest.approx(density * size ** 3, rel=1e-6)
            seen.add(label)
    assert seen == {"small", "large"}

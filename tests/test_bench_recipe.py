"""The `bench` recipe (no rendering): a complete scene directory from the seed alone, documented,
packable, and loaded back as the arrays numpy's RandomState gives for that seed."""

import numpy as np

from kubric import docgen
from kubric.datasets import load, pack
from kubric.pipeline.worker import SUCCESS, run_scene
from kubric.recipes.bench import Bench


def expected(seed, w=8, h=8, t=2, n=3):
    """The draws the recipe documents, in its order (an independent restatement)."""
    rng = np.random.RandomState(seed)
    rgba = rng.randint(0, 256, size=(t, h, w, 4)).astype(np.uint8)
    seg = rng.randint(0, n + 1, size=(t, h, w, 1)).astype(np.uint8)
    positions = rng.uniform(-1.0, 1.0, size=(n, t, 3)).astype(np.float32)
    return rgba, seg, positions


def test_bench_scene_is_complete_documented_and_deterministic(tmp_path):
    a = run_scene(Bench(), 5, tmp_path / "a").path
    b = run_scene(Bench(), 5, tmp_path / "b").path
    c = run_scene(Bench(), 6, tmp_path / "c").path
    names = sorted(p.name for p in a.iterdir())
    assert names == [SUCCESS, "events.json", "metadata.json", "rgba_00000.png", "rgba_00001.png",
                     "schema.json", "segmentation_00000.png", "segmentation_00001.png"]
    same = [n for n in names if n != SUCCESS]
    assert all((a / n).read_bytes() == (b / n).read_bytes() for n in same)
    assert (a / "rgba_00000.png").read_bytes() != (c / "rgba_00000.png").read_bytes()
    assert docgen.undocumented_scene_fields(a) == []


def test_bench_scenes_pack_and_load_as_their_seeds_say(tmp_path):
    for seed in range(6):
        run_scene(Bench(), seed, tmp_path / "scenes")
    result = pack(tmp_path / "scenes", tmp_path / "ds", splits="train=1", progress=False)
    assert result.counts == {"train": 6}
    source = load(tmp_path / "ds", "train")
    for index, scene in enumerate(source.scenes):
        seed = int(scene.split("_")[1])
        rgba, seg, positions = expected(seed)
        example = source[index]
        assert example["metadata"]["seed"] == seed and example["metadata"]["num_frames"] == 2
        assert np.array_equal(example["video"], rgba[..., :3])
        assert np.array_equal(example["segmentations"], seg)
        assert np.array_equal(example["instances"]["positions"], positions)

"""``kubric.datasets.to_tf``: a real ``tf.data.Dataset`` whose examples equal the numpy loader's
(issue #33: TFDS 4.9.10's ``as_dataset`` refuses ArrayRecord shards). Two tiny MOVi-A scenes
(raycast) packed into two shards; every feature of every example compared, TensorFlow's decode
(TFDS's connectors in the graph) against ``kubric.datasets.load`` (TFDS's numpy decoders).
"""

import sys

import numpy as np
import pytest

from kubric.datasets import layout, load
from kubric.datasets.tfds_io import flatten
from tests.test_every_recipe import _kubric

OPTIONS = ["renderer=raycast", "resolution=24x16", "frame_end=3", "min_num_objects=2",
           "max_num_objects=3"]



@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    root = tmp_path_factory.mktemp("tf")
    sets = [a for o in OPTIONS for a in ("--set", o)]
    for seed in (1, 2):
        _kubric("worker", "movi_a", "--seed", seed, "--out", root / "scenes", *sets)
    _kubric("pack", root / "scenes", "--out", root / "ds", "--splits", "train=1",
            "--examples-per-shard", 1, "--no-progress")
    return root / "ds"


def _numpy(value):
    """A TensorFlow value as the numpy loader gives it: text → str, ragged → list of rows."""
    import tensorflow as tf
    if isinstance(value, tf.RaggedTensor):
        return [row.numpy() for row in value]
    arr = value.numpy()
    if value.dtype == tf.string:  # a scalar string is bytes, a vector an object array
        return arr.decode() if isinstance(arr, bytes) else [v.decode() for v in arr]
    return arr


def test_to_tf_examples_equal_the_numpy_loader(dataset):
    tf = pytest.importorskip("tensorflow")
    from kubric.datasets import to_tf
    data = to_tf(dataset, "train")
    assert isinstance(data, tf.data.Dataset)
    assert int(data.cardinality()) == 2
    source = load(dataset, "train")
    assert len(layout.read_info(dataset)["shard_lengths"]["train"]) == 2  # two shards read
    got = list(data)
    assert len(got) == len(source)
    for index, example in enumerate(got):
        want, have = flatten(source[index]), flatten(example)
        assert sorted(have) == sorted(want)
        for name, expected in want.items():
            value = _numpy(have[name])
            if isinstance(expected, list):
                assert len(value) == len(expected), name
                for a, b in zip(value, expected, strict=True):
                    assert np.array_equal(np.asarray(a), np.asarray(b)), name
                    assert isinstance(b, str) or np.asarray(a).dtype == np.asarray(b).dtype, name
            else:
                assert np.asarray(value).dtype == np.asarray(expected).dtype, name
                assert np.array_equal(value, expected), name
    assert source[0]["metadata"]["video_name"] != source[1]["metadata"]["video_name"]
    # a second pass (fresh shard readers) and batching work as any tf.data pipeline
    names = [ex["metadata"]["video_name"].numpy().decode() for ex in data]
    assert names == [source[i]["metadata"]["video_name"] for i in range(2)]
    video = next(iter(data.map(lambda ex: ex["video"]).batch(2)))
    assert video.shape == (2, 3, 16, 24, 3) and video.dtype == tf.uint8


def test_to_tf_bad_split_is_one_line(dataset):
    pytest.importorskip("tensorflow")
    from kubric.datasets import to_tf
    with pytest.raises(layout.DatasetError, match="has no split 'test'"):
        to_tf(dataset, "test")


def test_to_tf_without_tensorflow_is_one_line(dataset, monkeypatch):
    """TensorFlow's absence simulated: ``sys.modules["tensorflow"] = None`` makes both
    ``importlib.util.find_spec`` and ``import tensorflow`` see no TensorFlow."""
    from kubric.datasets import to_tf
    monkeypatch.setitem(sys.modules, "tensorflow", None)
    with pytest.raises(layout.DatasetError, match=r"tf.data needs TensorFlow, which is not "
                                                  r"installed \(pip install 'kubric\[tf\]'"):
        to_tf(dataset, "train")

"""The sharded packer (kubric.datasets.dask_pack) in this process, on tiny scenes of a toy schema
(no rendering): bit-identical to the local packer from a directory and from a URL (file://, read
through fsspec as an object store would be), with an incomplete and a corrupt scene (the re-cut
path). The Dask and S3 runs are in test_pack_cluster.py."""

import numpy as np
import pytest

from kubric.datasets import dask_pack, packer
from kubric.io.scene_writer import write_scene
from kubric.io.schema import Feature, Schema, register_schema
from kubric.pipeline import Recipe
from kubric.pipeline.worker import run_scene

T, H, W = 2, 4, 5
SCHEMA = register_schema(Schema("test_pack_sharded", (
    Feature("metadata/video_name", "str", (), "scene_name", "text"),
    Feature("metadata/seed", "int64", (), "meta:seed"),
    Feature("video", "uint8", ("T", "H", "W", 3), "layer:rgba[:3]", "png"),
)))


class Tiny(Recipe, name="test_pack_sharded"):
    """Random RGB frames."""

    schema = SCHEMA

    def generate(self, seed, out_dir):
        rgba = np.random.RandomState(seed).randint(0, 256, size=(T, H, W, 4)).astype(np.uint8)
        metadata = {"flags": self.flags(seed),
                    "metadata": {"resolution": [W, H], "num_frames": T, "seed": seed}}
        write_scene(self.schema, out_dir, {"rgba": rgba}, metadata)


def tree(folder):
    return {p.relative_to(folder).as_posix(): p.read_bytes()
            for p in sorted(folder.rglob("*")) if p.is_file()}


@pytest.fixture(scope="module")
def scenes(tmp_path_factory):
    root = tmp_path_factory.mktemp("sharded")
    for seed in range(9):
        run_scene(Tiny(), seed, root / "clean")
    import shutil
    shutil.copytree(root / "clean", root / "bad")
    (root / "bad" / "scene_00000006" / "_SUCCESS").unlink()
    (root / "bad" / "scene_00000003" / "rgba_00001.png").write_bytes(b"not a png")
    return root


KW = dict(splits="train=0.5,validation=0.5", examples_per_shard=2, progress=False)


@pytest.mark.parametrize("name", ["clean", "bad"])
def test_sharded_pack_equals_local_pack(scenes, tmp_path, name):
    ref = packer.pack(scenes / name, tmp_path / "ref", **KW)
    assert sum(ref.counts.values()) == (9 if name == "clean" else 7)
    expected = tree(tmp_path / "ref")
    assert len([k for k in expected if ".array_record-" in k]) >= 3
    for k, location in enumerate([scenes / name, f"file://{scenes / name}"]):
        out = tmp_path / f"got{k}"
        got = dask_pack.pack_sharded(location, out, **KW)
        assert tree(out) == expected, [f for f in expected if tree(out).get(f) != expected[f]]
        assert got.counts == ref.counts and got.incomplete == ref.incomplete
        assert [c[1].replace(f"file://{scenes}", str(scenes)) for c in got.corrupt] == \
            [c[1] for c in ref.corrupt]
        if name == "bad":
            assert got.corrupt[0][0] == f"{location}/scene_00000003"
    assert not list(tmp_path.glob(".*incomplete*"))


def test_sharded_pack_bad_input(scenes, tmp_path):
    with pytest.raises(packer.DatasetError, match="is not a directory"):
        dask_pack.pack_sharded(tmp_path / "none", tmp_path / "a", **KW)
    with pytest.raises(packer.DatasetError, match="does not exist"):
        dask_pack.pack_sharded(f"file://{tmp_path}/none", tmp_path / "a", **KW)
    with pytest.raises(packer.DatasetError, match="--verify compares with local scene"):
        dask_pack.pack_sharded(f"file://{scenes}/clean", tmp_path / "a", verify=True, **KW)
    with pytest.raises(packer.DatasetError, match="fractions must sum to 1"):
        dask_pack.pack_sharded(scenes / "clean", tmp_path / "a", splits="train=0.5",
                               examples_per_shard=2, progress=False)
    assert not (tmp_path / "a").exists() and not list(tmp_path.glob(".*incomplete*"))


def test_a_worker_that_cannot_see_the_output_fails_in_one_line(scenes, tmp_path):
    with pytest.raises(packer.DatasetError, match=r"^the pack worker on .* cannot see '.*/nfs/"
                       r"\.ds\.incomplete': --out must be on a filesystem shared with the "
                       r"workers$"):
        dask_pack.encode_chunk(str(tmp_path / "nfs" / ".ds.incomplete"), "x-train.chunk-00000",
                               [str(scenes / "clean" / "scene_00000000")], SCHEMA,
                               {"T": T, "H": H, "W": W})

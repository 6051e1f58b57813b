"""AssetSource: manifests, create(), test splits, safe extraction of hostile archives."""

from __future__ import annotations

import io
import json
import os
import tarfile

import numpy as np
import pytest

import kubric as kb
from kubric.assets import (
    AssetSource,
    CorruptArchiveError,
    ManifestError,
    UnsafeArchiveError,
    cache_dir,
    safe_extract,
)
from kubric.assets.archive import write_archive


# ----------------------------------------------------------------------------- helpers
def _entry(asset_id, asset_type="Texture", **extra):
    entry = {"id": asset_id, "asset_type": asset_type, "license": "CC0-1.0",
             "kwargs": {"filename": "{asset_dir}/image.png", "mapping": "environment"},
             "metadata": {"category": "test"}}
    entry.update(extra)
    return entry


def _texture_source(root, ids=("alpha", "beta", "gamma")):
    """A source of tiny texture assets, each archive holding image.png and data.json."""
    root.mkdir(parents=True, exist_ok=True)
    assets = {}
    for asset_id in ids:
        stage = root / f"stage_{asset_id}"
        stage.mkdir()
        (stage / "image.png").write_bytes(b"\x89PNG fake " + asset_id.encode())
        entry = _entry(asset_id)
        (stage / "data.json").write_text(json.dumps(entry))
        write_archive(stage, root / f"{asset_id}.tar.gz")
        assets[asset_id] = entry
    (root / "manifest.json").write_text(json.dumps({"name": "T", "version": "1",
                                                    "assets": assets}))
    return root


def _tar_with(path, members):
    """members: list of (TarInfo, bytes or None)."""
    with tarfile.open(path, "w:gz") as tar:
        for info, data in members:
            tar.addfile(info, io.BytesIO(data) if data is not None else None)
    return path


def _file(name, data=b"x"):
    info = tarfile.TarInfo(name)
    info.size = len(data)
    return info, data


def _snapshot(root):
    return sorted(str(p.relative_to(root)) for p in root.rglob("*"))


@pytest.fixture(autouse=True)
def _isolated_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("KUBRIC_CACHE_DIR", str(tmp_path / "cache"))


# ----------------------------------------------------------------------------- source API
def test_cache_dir_from_environment(tmp_path):
    assert cache_dir() == tmp_path / "cache"


def test_create_resolves_asset_dir_and_copies_metadata(tmp_path):
    source = kb.AssetSource(_texture_source(tmp_path / "src"))
    assert source.all_asset_ids == ["alpha", "beta", "gamma"]
    assert source.categories == ["test"]
    tex = source.create("beta", strength=2.0)
    assert isinstance(tex, kb.Texture)
    assert tex.mapping == "environment" and tex.strength == 2.0
    assert os.path.isfile(tex.filename)
    assert open(tex.filename, "rb").read() == b"\x89PNG fake beta"
    assert str(tmp_path / "cache") in tex.filename  # extracted into the cache
    assert tex.metadata["asset_id"] == "beta" and tex.metadata["category"] == "test"
    assert tex.metadata["license"] == "CC0-1.0"
    source.cleanup()
    assert not os.path.exists(tex.filename)
    assert os.path.isfile(source.create("beta").filename)  # extracted again on demand
    # a rebuilt archive is extracted afresh, not served from the stale copy
    stage = tmp_path / "src" / "stage_beta"
    (stage / "image.png").write_bytes(b"\x89PNG new content")
    write_archive(stage, tmp_path / "src" / "beta.tar.gz")
    assert open(source.create("beta").filename, "rb").read() == b"\x89PNG new content"


def test_from_manifest_path_and_did_you_mean(tmp_path):
    source = AssetSource.from_manifest(_texture_source(tmp_path / "src") / "manifest.json")
    with pytest.raises(KeyError, match=r"'betta'.*did you mean \['beta'\]"):
        source.create("betta")


def test_test_split_is_deterministic_and_disjoint(tmp_path):
    ids = [f"a{i:02d}" for i in range(20)]
    root = tmp_path / "src"
    root.mkdir()
    (root / "manifest.json").write_text(json.dumps(
        {"name": "S", "assets": {i: _entry(i) for i in ids}}))
    source = AssetSource(root)
    train, test = source.get_test_split(fraction=0.1, seed=3)
    assert len(test) == 2 and len(train) == 18
    assert sorted(train + test) == ids
    assert source.get_test_split(fraction=0.1, seed=3) == (train, test)
    assert source.get_test_split(fraction=0.5, seed=4)[1] != source.get_test_split(0.5, 5)[1]
    with pytest.raises(ValueError, match="fraction"):
        source.get_test_split(fraction=1.5)


@pytest.mark.parametrize("breakage, message", [
    (lambda m: m.pop("assets"), "missing required field 'assets'"),
    (lambda m: m["assets"]["alpha"].pop("kwargs"), "asset 'alpha': missing required field "
                                                   "'kwargs'"),
    (lambda m: m["assets"]["alpha"].update(asset_type="Mesh"),
     "unknown asset_type 'Mesh'; allowed: \\['FileBasedObject', 'Texture', 'Character', "
     "'MotionClip'\\]"),
    (lambda m: m["assets"]["alpha"].update(id="other"), "must equal its key"),
])
def test_bad_manifest_is_a_clear_error(tmp_path, breakage, message):
    root = _texture_source(tmp_path / "src", ids=("alpha",))
    manifest = json.loads((root / "manifest.json").read_text())
    breakage(manifest)
    (root / "manifest.json").write_text(json.dumps(manifest))
    with pytest.raises(ManifestError, match=message):
        AssetSource(root)


def test_missing_and_corrupt_archives_name_the_asset(tmp_path):
    root = _texture_source(tmp_path / "src", ids=("alpha", "beta"))
    (root / "alpha.tar.gz").unlink()
    data = (root / "beta.tar.gz").read_bytes()
    (root / "beta.tar.gz").write_bytes(data[: len(data) // 2])
    source = AssetSource(root)
    with pytest.raises(CorruptArchiveError, match="asset 'alpha'.*missing"):
        source.create("alpha")
    with pytest.raises(CorruptArchiveError, match="asset 'beta'"):
        source.create("beta")
    assert [p for p in source.scratch_dir.iterdir()] == []  # nothing half-extracted is kept


def test_written_archives_are_byte_identical(tmp_path):
    for name in ("a", "b"):
        stage = tmp_path / f"stage_{name}"
        (stage / "sub").mkdir(parents=True)
        (stage / "sub" / "x.txt").write_text("hello")
        (stage / "data.json").write_text("{}")
        os.utime(stage / "data.json", (1e9 if name == "a" else 2e9,) * 2)
        write_archive(stage, tmp_path / f"{name}.tar.gz")
    assert (tmp_path / "a.tar.gz").read_bytes() == (tmp_path / "b.tar.gz").read_bytes()
    with tarfile.open(tmp_path / "a.tar.gz") as tar:
        assert [m.name for m in tar.getmembers()] == ["data.json", "sub/x.txt"]
        assert all(m.mtime == 0 and m.uid == 0 for m in tar.getmembers())


# ----------------------------------------------------------------------------- hostile archives
def _symlink(name, target):
    info = tarfile.TarInfo(name)
    info.type = tarfile.SYMTYPE
    info.linkname = target
    return info, None


def _hardlink(name, target):
    info = tarfile.TarInfo(name)
    info.type = tarfile.LNKTYPE
    info.linkname = target
    return info, None


def _device(name):
    info = tarfile.TarInfo(name)
    info.type = tarfile.CHRTYPE
    info.devmajor, info.devminor = 1, 3
    return info, None


@pytest.mark.parametrize("members, message", [
    ([_file("ok.txt"), _file("../../evil", b"pwned")], r"'\.\./\.\./evil'.*leaves"),
    ([_file("sub/../../evil", b"pwned")], "leaves"),
    ([_file("/tmp/kubric_absolute_evil", b"pwned")], "absolute path"),
    ([_file("ok.txt"), _symlink("link", "/etc/passwd")], "is a link"),
    ([_symlink("dir", ".."), _file("dir/evil", b"pwned")], "is a link"),
    ([_file("ok.txt"), _hardlink("hard", "/etc/passwd")], "is a link"),
    ([_device("null")], "device"),
])
def test_hostile_archive_is_refused_and_writes_nothing(tmp_path, members, message):
    archive = _tar_with(tmp_path / "evil.tar.gz", members)
    jail = tmp_path / "jail"
    jail.mkdir()
    target = jail / "cache" / "asset"
    before = _snapshot(tmp_path)
    with pytest.raises(UnsafeArchiveError, match=message) as err:
        safe_extract(archive, target, asset_id="evil_asset")
    assert "evil_asset" in str(err.value)
    after = [p for p in _snapshot(tmp_path) if p not in before]
    assert after == ["jail/cache"], after  # only the (empty) parent of the target was created
    assert list((jail / "cache").iterdir()) == []
    assert not os.path.exists("/tmp/kubric_absolute_evil")
    assert not (tmp_path / "evil").exists() and not (tmp_path.parent / "evil").exists()


def test_oversize_member_is_refused(tmp_path):
    archive = _tar_with(tmp_path / "big.tar.gz", [_file("big.bin", b"0" * 5000)])
    with pytest.raises(UnsafeArchiveError, match="5000 bytes, more than the limit of 1000"):
        safe_extract(archive, tmp_path / "out", asset_id="big", max_member_bytes=1000)
    with pytest.raises(UnsafeArchiveError, match="add up to"):
        safe_extract(archive, tmp_path / "out", asset_id="big", max_total_bytes=1000)
    assert not (tmp_path / "out").exists()


def test_hostile_asset_through_asset_source(tmp_path):
    root = _texture_source(tmp_path / "src", ids=("alpha",))
    _tar_with(root / "alpha.tar.gz", [_file("image.png"), _file("../../../evil", b"pwned")])
    source = AssetSource(root)
    with pytest.raises(UnsafeArchiveError, match="asset 'alpha'"):
        source.create("alpha")
    written = [p for p in (tmp_path / "cache").rglob("*") if p.is_file()]
    assert written == []
    assert not any(p.name == "evil" for p in tmp_path.rglob("*"))


def test_safe_extract_keeps_nested_files(tmp_path):
    archive = _tar_with(tmp_path / "ok.tar.gz", [_file("a/b/c.txt", b"deep"), _file("d.txt")])
    out = safe_extract(archive, tmp_path / "out", asset_id="ok")
    assert (out / "a" / "b" / "c.txt").read_bytes() == b"deep"
    assert np.array_equal(sorted(os.listdir(out)), ["a", "d.txt"])


def test_categories_filter_and_split_per_category(tmp_path):
    import numpy as np

    root = tmp_path / "src"
    root.mkdir()
    assets = {}
    for i in range(30):
        entry = _entry(f"m{i:02d}")
        entry["metadata"] = {"category": ["mug", "shoe", "toy"][i % 3]}
        if i % 5 == 0:
            entry["metadata"]["categories"] = [entry["metadata"]["category"], "kitchen"]
        assets[entry["id"]] = entry
    (root / "manifest.json").write_text(json.dumps({"name": "C", "assets": assets}))
    source = AssetSource(root)
    assert source.categories == ["kitchen", "mug", "shoe", "toy"]
    assert source.asset_ids_in("kitchen") == [f"m{i:02d}" for i in range(0, 30, 5)]
    # the held-out ids: RandomState(42).choice(sorted ids, 3) over the whole source, then filtered
    held = set(np.random.RandomState(42).choice(sorted(assets), 3, replace=False).tolist())
    mugs = [f"m{i:02d}" for i in range(0, 30, 3)]
    assert source.asset_ids("mug", split="test") == sorted(held & set(mugs))
    assert source.asset_ids(["mug"], split="train") == sorted(set(mugs) - held)
    assert source.asset_ids(["mug", "toy"]) == sorted(a for a in assets
                                                    if int(a[1:]) % 3 in (0, 2))
    train, test = source.get_test_split(category="shoe")
    shoes = [f"m{i:02d}" for i in range(1, 30, 3)]
    assert test == [np.random.RandomState(42).choice(shoes, 1, replace=False)[0]]
    assert sorted(train + test) == shoes
    with pytest.raises(KeyError, match=r"no categories \['hat'\]; categories: \['kitchen'"):
        source.asset_ids("hat")
    with pytest.raises(KeyError, match="no asset in category 'hat'"):
        source.get_test_split(category="hat")
    with pytest.raises(ValueError, match="split must be"):
        source.asset_ids(split="val")

"""Round-two hostile tests (issue #27) of the CLI's remaining surfaces: truncated tracks files,
track queries of the wrong shape, a full disk and a symlink while generating, a cache path that
is a file, option combinations that cannot succeed, and what --help / `kubric recipes` promise."""

import os
import pathlib
import subprocess
import sys

import pytest
from viewer_helpers import synthetic_scene

from kubric.pipeline.options import OptionError
from kubric.pipeline.recipe import get_recipe

ROOT = pathlib.Path(__file__).resolve().parents[1]
FAKE = f"{ROOT / 'tests' / 'fake_recipes.py'}:Fake"


def kubric(*args, env=None, cwd=None):
    return subprocess.run([sys.executable, "-m", "kubric", *map(str, args)], capture_output=True,
                          text=True, timeout=300, env={**os.environ, **(env or {})}, cwd=cwd)


def one_line(run, code, *needles):
    assert run.returncode == code, (run.returncode, run.stderr)
    line, = run.stderr.strip().splitlines()
    for needle in needles:
        assert needle in line, line
    return line


@pytest.fixture()
def truncated_tracks(tmp_path):
    scene = tmp_path / "scenes" / "scene_00000003"
    synthetic_scene(scene)
    (scene / "tracks.npz").write_bytes(b"PK\x03\x04" + b"\x00" * 20)
    return scene


def test_item14_truncated_tracks_named_by_export_and_inspect(truncated_tracks, tmp_path):
    where = f"{str(truncated_tracks / 'tracks.npz')!r} is not a readable tracks file (truncated"
    one_line(kubric("export", "tapvid", truncated_tracks.parent, "--out", tmp_path / "t.pkl"),
             1, where)  # bad input: 1 in every command (docs/exit-codes.md)
    one_line(kubric("inspect", truncated_tracks, "--sheet", tmp_path / "s.png"), 1, where)
    (truncated_tracks / "tracks.npz").write_bytes(b"\x93NUMPY garbage that is no zip")
    one_line(kubric("inspect", truncated_tracks, "--sheet", tmp_path / "s.png"), 1, where)


def test_item14_track_queries_json_object(tmp_path):
    queries = tmp_path / "q.json"
    queries.write_text('{"t": 0, "y": 1, "x": 2}')
    with pytest.raises(OptionError, match=rf"option track_queries: cannot read queries from "
                       rf"'{queries}': expected rows \(t, y, x\)"):
        get_recipe("movi_a").from_assignments([f"track_queries={queries}"]).prepare()


def test_item17_full_disk_while_generating_names_the_scene(tmp_path):
    run = kubric("worker", FAKE, "--seed", "3", "--out", tmp_path / "out",
                 env={"KUBRIC_FAULT": "worker.generated:enospc"})
    line = one_line(run, 1, "No space left on device (writing the scene;", "MiB free there)")
    assert f"{tmp_path / 'out'}/.scene_00000003.incomplete-" in line
    assert [p.name for p in (tmp_path / "out").iterdir()] == []


def test_item17_symlink_at_scene_name_and_cache_file(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (tmp_path / "elsewhere").mkdir()
    (out / "scene_00000001").symlink_to(tmp_path / "elsewhere")
    one_line(kubric("worker", FAKE, "--seed", "1", "--out", out), 1,
             f"{out / 'scene_00000001'}: a symbolic link stands at the scene's name")
    assert (out / "scene_00000001").is_symlink()  # not followed, not removed
    cache = tmp_path / "cache-file"
    cache.write_text("not a folder")
    from kubric.assets.asset_source import cache_dir
    os.environ["KUBRIC_CACHE_DIR"], saved = str(cache), os.environ.get("KUBRIC_CACHE_DIR")
    try:
        with pytest.raises(NotADirectoryError, match="must be a directory, this is a file"):
            cache_dir()
    finally:
        os.environ["KUBRIC_CACHE_DIR"] = saved
    run = kubric("worker", "movi_a", "--seed", "0", "--out", tmp_path / "o2",
                 env={"KUBRIC_CACHE_DIR": str(cache)})
    one_line(run, 1, f"{cache}: the asset cache (KUBRIC_CACHE_DIR) must be a directory")


@pytest.mark.parametrize("recipe,options,needle", [
    ("klevr", ["region=0.5", "min_num_objects=12"], "cannot stand apart in region=±0.5 m"),
    ("complex_brdf", ["object_size=1e30"], "does not fit inside orbit_distance=6 m"),
    ("complex_brdf", ["object_size=5", "light_distance=4"],
     "does not fit inside light_distance=4 m"),
])
def test_item18_impossible_combinations_refused_before_rendering(recipe, options, needle):
    with pytest.raises(OptionError, match=needle):
        get_recipe(recipe).from_assignments(options).prepare()


def test_item18_klevr_bound_is_an_upper_bound():
    """The refused counts cannot be placed: the bound is above what the placer achieves."""
    import numpy as np

    from kubric.recipes.klevr import max_objects_on_floor
    from kubric.recipes.multiview_base import free_place
    for region, radius in [(0.5, 0.4), (1.0, 0.4), (2.0, 0.5), (3.5, 0.4)]:
        rng = np.random.RandomState(0)
        occupied = []
        while free_place(rng, occupied, radius, region, max_trials=20000) is not None:
            pass
        assert len(occupied) <= max_objects_on_floor(region, radius), (region, radius)
    get_recipe("klevr").from_assignments([]).prepare()  # the defaults still pass


def test_item19_help_and_recipes_say_what_is_allowed():
    helptext = kubric("generate", "--help").stdout
    assert "not memory://" in " ".join(helptext.split())
    listing = kubric("recipes", "movi_a").stdout
    assert "[allowed: " in listing
    resolution = next(ln for ln in listing.splitlines() if ln.strip().startswith("resolution"))
    assert "≤ 8192" in resolution

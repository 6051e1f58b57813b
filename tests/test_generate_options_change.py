"""A re-run of `kubric generate` into a folder whose scenes other options made refuses in one line
(naming the options and the ways out); an unchanged re-run resumes; --overwrite makes the seeds
again; --resume-any keeps what is there. Real processes, the bench recipe (whose scenes store
their options in schema.json) and the test recipe (metadata.json only, as older scenes)."""

import json
import pathlib
import subprocess
import sys

from kubric.io.scene_dir import is_complete

ROOT = pathlib.Path(__file__).resolve().parents[1]
FAKE = f"{ROOT / 'tests' / 'fake_recipes.py'}:Fake"


def generate(out, recipe, *args):
    return subprocess.run([sys.executable, "-m", "kubric", "generate", recipe, "--out", str(out),
                           "--no-progress", "--retries", "0", *args], cwd=ROOT,
                          capture_output=True, text=True, timeout=300)


def options_of(scene: pathlib.Path) -> dict:
    return json.loads((scene / "schema.json").read_text())["options"]


def test_changed_options_refuse_unchanged_resume(tmp_path):
    out = tmp_path / "scenes"
    first = generate(out, "bench", "--scenes", "3", "--set", "frames=2")
    assert first.returncode == 0, first.stderr
    stamp = (out / "scene_00000001" / "_SUCCESS").stat().st_mtime_ns

    again = generate(out, "bench", "--scenes", "3", "--set", "frames=2")
    assert again.returncode == 0 and "0 generated, 3 already complete" in again.stdout

    changed = generate(out, "bench", "--scenes", "3", "--set", "frames=3")
    lines = changed.stderr.strip().splitlines()
    assert changed.returncode == 2 and len(lines) == 1, changed.stderr
    assert "frames (2 there, 3 now)" in lines[0]
    for way in ("new --out", "--overwrite", "--resume-any"):
        assert way in lines[0]
    # adding seeds with other options to these scenes refuses too (one scene of the folder read)
    more = generate(out, "bench", "--scenes", "2", "--first-seed", "3", "--set", "frames=3")
    assert more.returncode == 2 and "frames (2 there, 3 now)" in more.stderr
    assert not (out / "scene_00000003").exists()
    assert (out / "scene_00000001" / "_SUCCESS").stat().st_mtime_ns == stamp  # untouched

    kept = generate(out, "bench", "--scenes", "3", "--set", "frames=3", "--resume-any")
    assert kept.returncode == 0 and "3 already complete" in kept.stdout
    assert options_of(out / "scene_00000001")["frames"] == 2

    redone = generate(out, "bench", "--scenes", "2", "--set", "frames=3", "--overwrite")
    assert redone.returncode == 0 and "2 generated" in redone.stdout, redone.stdout
    assert "2 complete scenes replaced" in redone.stdout
    assert [options_of(out / f"scene_{s:08d}")["frames"] for s in range(3)] == [3, 3, 2]
    assert len(list((out / "scene_00000000").glob("rgba_*.png"))) == 3
    both = generate(out, "bench", "--scenes", "1", "--overwrite", "--resume-any")
    assert both.returncode == 2 and "not allowed with" in both.stderr


def test_older_scenes_without_schema_json_are_compared_by_their_metadata(tmp_path):
    out = tmp_path / "scenes"
    assert generate(out, FAKE, "--scenes", "2", "--set", "frames=2").returncode == 0
    assert not (out / "scene_00000000" / "schema.json").exists()  # the test recipe writes none
    changed = generate(out, FAKE, "--scenes", "2", "--set", "resolution=10x6", "--set", "frames=2")
    assert changed.returncode == 2
    assert "resolution ([8, 6] there, [10, 6] now)" in changed.stderr
    same = generate(out, FAKE, "--scenes", "2", "--set", "frames=2")
    assert same.returncode == 0 and "2 already complete" in same.stdout
    other_recipe = generate(out, "bench", "--scenes", "2")
    assert other_recipe.returncode == 2 and '"test_fake" there, "bench" now' in other_recipe.stderr
    assert all(is_complete(out / f"scene_{s:08d}") for s in range(2))


def test_an_option_added_since_a_scene_was_made_counts_as_its_default(tmp_path):
    """A scene made before the recipe had ``num_instances`` does not record it (simulated by
    removing it from the scene's schema.json and metadata.json): the default resumes, another
    value refuses."""
    out = tmp_path / "scenes"
    assert generate(out, "bench", "--scenes", "2").returncode == 0
    for scene in out.glob("scene_*"):
        for name, key in (("schema.json", "options"), ("metadata.json", "flags")):
            doc = json.loads((scene / name).read_text())
            del doc[key]["num_instances"]
            (scene / name).write_text(json.dumps(doc))
    same = generate(out, "bench", "--scenes", "2")
    assert same.returncode == 0 and "2 already complete" in same.stdout, same.stderr
    other = generate(out, "bench", "--scenes", "2", "--set", "num_instances=2")
    assert other.returncode == 2 and "num_instances (3 there, 2 now)" in other.stderr

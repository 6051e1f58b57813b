"""The repository's docs cover the code: generated pages are current, every recipe option has a
meaning, every file and field a scene directory holds is named in docs/scene-format.md."""

import json
import shutil

from kubric import docgen
from kubric.pipeline import Option, Recipe


def test_generated_pages_are_current():
    assert docgen.stale_pages() == [], "run `make docs` (python -m kubric.docgen)"


def test_check_mode_reports_a_stale_page(tmp_path, capsys):
    docgen.write_pages(tmp_path)
    assert docgen.main(["--check", "--out", str(tmp_path)]) == 0
    page = tmp_path / "recipes.md"
    page.write_text(page.read_text().replace("| samples |", "| spp |"))
    assert docgen.main(["--check", "--out", str(tmp_path)]) == 1
    assert "docs/recipes.md is out of date" in capsys.readouterr().err


def test_every_builtin_recipe_option_has_a_meaning():
    from kubric.pipeline.recipe import load_builtin
    assert docgen.undocumented_options(load_builtin().values()) == []
    page = (docgen.docs_dir() / "recipes.md").read_text()
    for name, cls in load_builtin().items():
        assert f"### `{name}`" in page
        for option in cls.options:
            assert f"| {option} |" in page, (name, option)


def test_an_option_without_meaning_is_reported():
    class Undocumented(Recipe, name="_docs_probe"):
        quiet = Option(1)

        def generate(self, seed, out_dir):  # pragma: no cover - never run
            raise AssertionError

    from kubric.pipeline.recipe import REGISTRY
    try:
        assert docgen.undocumented_options([Undocumented]) == ["_docs_probe.quiet"]
    finally:
        REGISTRY.pop("_docs_probe", None)


def test_undocumented_scene_fields_are_reported(tmp_path):
    """A scene directory with a file and fields the page does not name is flagged (the MOVi test
    runs the same check on real scenes)."""
    scene = tmp_path / "scene_00000000"
    scene.mkdir()
    (scene / "rgba_00000.png").write_bytes(b"")
    (scene / "sparkle_00000.png").write_bytes(b"")
    (scene / "metadata.json").write_text(json.dumps({
        "flags": {"recipe": "movi_a", "seed": 0, "samples": 4, "mystery": 1},
        "metadata": {"resolution": [4, 4], "vibe": "calm"},
        "camera": {"K": []}, "instances": [{"mass": 1.0, "aura": 2}]}))
    (scene / "events.json").write_text(json.dumps({"collisions": [{"force": 1.0, "sound": 3}]}))
    (scene / "data_ranges.json").write_text(json.dumps({"forward_flow": {}}))
    assert docgen.undocumented_scene_fields(scene) == [
        "collisions.sound", "file sparkle_{i:05d}.png", "flags.mystery (not an option of movi_a)",
        "instances.aura", "metadata.vibe"]
    shutil.rmtree(scene)


def test_recipes_page_says_shared_text_once_and_every_default_where_linked():
    """docs/recipes.md writes a family's shared text once (no paragraph twice), and each recipe's
    options appear, with the default the recipe really uses (its ``options``), either in its own
    table or in a shared group its section links to."""
    import re

    from kubric.pipeline.recipe import load_builtin
    page = docgen.recipes_markdown()
    paragraphs = [p for p in page.split("\n\n") if len(p) > 80 and not p.startswith(
        ("|", "Shared options:", "Builds on"))]
    assert len(paragraphs) == len(set(paragraphs)), [p[:60] for p in paragraphs
                                                     if paragraphs.count(p) > 1]
    groups = {m.group(1): m.group(2) for m in re.finditer(
        r'<a id="(options-[^"]+)"></a>\n\n### `[^`]+` options\n(.*?)(?=\n<a id=|\n## |\n### )',
        page, re.S)}

    def rows(text):
        return {line.split(" | ")[0][2:]: line.split(" | ")[2]
                for line in text.splitlines() if line.startswith("| ") and
                not line.startswith(("| option ", "| `"))}
    for name, cls in load_builtin().items():
        section = re.search(rf"\n### `{name}`\n(.*?)(?=\n### |\n## |\Z)", page, re.S).group(1)
        shown = rows(section)
        for anchor, replaced in re.findall(r"\]\(#(options-[^)]+)\)(?: \(its ([^)]+) replaced\))?",
                                           section):
            group = rows(groups[anchor])
            for option in re.findall(r"`([^`]+)`", replaced):
                group.pop(option)
            assert not set(group) & set(shown), (name, anchor, set(group) & set(shown))
            shown.update(group)
        assert set(shown) == set(cls.options), (name, set(shown) ^ set(cls.options))
        for option, opt in cls.options.items():
            assert shown[option] == docgen._cell(docgen._default_text(opt)), (name, option)

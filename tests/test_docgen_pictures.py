"""The recipe pictures of docs/recipes.md (``python -m kubric.docgen_pictures``): every built-in
recipe has picture options its recipe accepts, the page shows each committed picture, and a
picture is the scene's first RGB frame over black, enlarged without smoothing (bench: no render)."""

import numpy as np
from PIL import Image

from kubric import docgen, docgen_pictures
from kubric.pipeline.recipe import get_recipe, load_builtin


def test_every_recipe_has_picture_options_it_accepts(tmp_path):
    assert sorted(docgen_pictures.PICTURE_OPTIONS) == sorted(load_builtin())
    for name in docgen_pictures.PICTURE_OPTIONS:  # raises on a bad option
        get_recipe(name).from_assignments(docgen_pictures.picture_options(name, tmp_path))


def test_the_page_shows_every_committed_picture():
    page = docgen.recipes_markdown()
    for name in load_builtin():
        path = docgen_pictures.picture_path(docgen.docs_dir(), name)
        assert (f"]({docgen.RECIPE_PICTURE.format(name=name)})" in page) == path.is_file(), name


def test_a_picture_is_the_first_rgb_frame_enlarged(tmp_path, capsys):
    assert docgen_pictures.main(["--only", "bench", "--docs", str(tmp_path)]) == 0
    picture = np.asarray(Image.open(tmp_path / "img" / "recipes" / "bench.png"))
    assert f"{tmp_path}/img/recipes/bench.png" in capsys.readouterr().out
    # the same scene again (bench is a pure function of the seed): RGBA over black, by hand
    from kubric.pipeline.worker import run_scene
    run_scene(get_recipe("bench").from_assignments(["resolution=64"]), 0, tmp_path / "s")
    rgba = np.asarray(Image.open(tmp_path / "s" / "scene_00000000" / "rgba_00000.png"))
    over = np.round(rgba[..., :3] * (rgba[..., 3:] / 255.0)).astype(np.uint8)
    z = docgen_pictures.ZOOM
    assert picture.shape == (64 * z, 64 * z, 3)
    for dy in range(z):
        for dx in range(z):
            assert np.abs(picture[dy::z, dx::z].astype(int) - over).max() <= 1


def test_an_unknown_recipe_is_refused(capsys):
    assert docgen_pictures.main(["--only", "movi_z"]) == 2
    assert "unknown recipe(s) movi_z; allowed: bench," in capsys.readouterr().err

"""Renderer capabilities (kubric.renderer.base) and the recipes' ``renderer`` option.

* Every registered recipe that builds a renderer offers ``renderer`` with the choices of
  BACKENDS (found from the recipe's source, not from the mixin that declares the option).
* Capabilities are answered without importing a backend (bpy blocked); a bad combination is one
  line naming the backend, the request and the backends that can — from a recipe's options, from
  a backend's settings or scene, and from ``save_state``.
* A few recipes make tiny scenes with ``renderer=raycast`` and bpy blocked (CPU is scarce: MOVi-A
  is covered by tests/test_renderer_raycast.py): klevr (multi-view, then ``kubric export nerf``
  read back through the transforms files), vbr (video with its LASR sequence) and svr (a
  transparent film).
"""

import inspect
import json
import os
import pathlib
import subprocess
import sys

import numpy as np
import pytest

import kubric as kb
from kubric.datasets.exports import nerf
from kubric.io import png_io, tiff_io
from kubric.pipeline import OptionError, get_recipe
from kubric.pipeline.recipe import load_builtin
from kubric.renderer import base

ROOT = pathlib.Path(__file__).resolve().parents[1]
NO_BPY = pathlib.Path(__file__).resolve().parent / "no_bpy"
ENV = dict(os.environ, PYTHONPATH=os.pathsep.join([str(NO_BPY), str(ROOT)]))


def kubric(*args, timeout=300):
    return subprocess.run([sys.executable, "-m", "kubric", *map(str, args)], cwd=ROOT, env=ENV,
                          capture_output=True, text=True, timeout=timeout)


def _builds_a_renderer(cls) -> bool:
    """Whether any class of the recipe's MRO (from kubric) calls ``renderer.create(``."""
    for klass in cls.__mro__:
        if klass.__module__.startswith("kubric.") and \
                "renderer.create(" in inspect.getsource(sys.modules[klass.__module__]):
            return True
    return False


# ------------------------------------------------------------------------------ the option
def test_every_recipe_that_renders_offers_every_backend():
    recipes = load_builtin()
    rendering = {name for name, cls in recipes.items() if _builds_a_renderer(cls)}
    assert len(rendering) >= 16 and "bench" not in rendering
    offering = {name for name, cls in recipes.items() if "renderer" in cls.options}
    assert offering == rendering
    for name in rendering:
        assert recipes[name].options["renderer"].choices == tuple(base.BACKENDS), name


# ------------------------------------------------------------------------------ capabilities
def test_capabilities_are_answered_without_importing_a_backend():
    code = ("import sys, kubric as kb; c = kb.renderer.capabilities; "
            "print(c('blender').photoreal, c('raycast').photoreal, sorted(c('blender').effects), "
            "sorted(c('raycast').effects), c('blender').can_save_state, "
            "c('raycast').can_save_state, kb.renderer.base.able(['motion_blur'])); "
            "assert not {'bpy', 'kubric.renderer.blender', 'kubric.renderer.raycast'} "
            "& set(sys.modules)")
    proc = subprocess.run([sys.executable, "-c", code], env=ENV, capture_output=True, text=True,
                          timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.split("\n")[0] == ("True False ['depth_of_field', 'motion_blur', "
                                          "'rolling_shutter'] ['rolling_shutter'] True False "
                                          "['blender']")


def test_capability_declarations_are_checked():
    with pytest.raises(ValueError, match=r"unknown effects \['bokeh'\]; allowed: "
                                         r"\['motion_blur', 'depth_of_field', 'rolling_shutter'\]"):
        base.Capabilities(effects={"bokeh"})
    with pytest.raises(ValueError, match=r"unknown layers \['albedo'\]"):
        base.Capabilities(layers=("rgba", "albedo"))
    with pytest.raises(ValueError, match="unknown renderer capability 'hdr'"):
        base.capabilities("raycast").has("hdr")
    with pytest.raises(ValueError, match=r"unknown renderer 'povray'; allowed: \['blender', "
                                         r"'raycast'\]"):
        base.capabilities("povray")
    # a rolling shutter: raycast, and blender (Cycles' RGB, raycast's exact layers)
    assert base.able(["rolling_shutter"]) == ["blender", "raycast"]
    assert base.refusal("raycast", {"motion_blur": "shutter=0.1"}, "x") == (
        "x: renderer=raycast cannot render motion blur (shutter=0.1); backends that can: "
        "blender")


def _scene(**camera):
    scene = kb.Scene(resolution=(8, 6), frame_start=0, frame_end=1)
    scene += kb.PerspectiveCamera(position=(0, -5, 0), look_at=(0, 0, 0), **camera)
    return scene


def test_a_backend_refuses_what_it_lacks_in_one_line(tmp_path):
    r = base.create("raycast", _scene())
    assert r.capabilities is base.BACKENDS["raycast"].capabilities
    assert r.layers == base.ALL_LAYERS
    with pytest.raises(base.CapabilityError) as err:
        r.save_state(tmp_path / "scene.blend")
    assert str(err.value) == (f"Raycast.save_state: renderer=raycast cannot save its state as a "
                              f"scene file (save_state('{tmp_path}/scene.blend')); backends "
                              "that can: blender")
    assert not list(tmp_path.iterdir())
    with pytest.raises(base.CapabilityError, match=r"^Raycast: renderer=raycast cannot render "
                       r"motion blur \(motion_blur=0.5\); backends that can: blender$"):
        base.create("raycast", _scene(), motion_blur=0.5)
    blurred = base.create("raycast", _scene(use_dof=True))
    with pytest.raises(base.CapabilityError, match=r"cannot render depth of field \(camera "
                       r"'PerspectiveCamera' use_dof=True\); backends that can: blender$"):
        blurred.render(return_layers=("depth",))


@pytest.mark.parametrize("recipe, options, request_", [
    ("movi_a", ["samples=4", "quality=fast"], "take the RGB quality settings (samples, "
     "denoising) (samples=4, quality=fast)"),
    ("movi_a", ["save_state=true"], "save its state as a scene file (save_state=True)"),
    ("movi_f", [], "render motion blur (max_motion_blur=2.0)"),
    ("complex_brdf", [], "render photoreal RGB (the complex_brdf recipe)"),
])
def test_a_recipe_asks_its_backend_and_refuses_in_one_line(recipe, options, request_):
    with pytest.raises(OptionError) as err:
        get_recipe(recipe).from_assignments(["renderer=raycast", *options])
    assert str(err.value) == (f"{recipe}: renderer=raycast cannot {request_}; backends that "
                              "can: blender")
    if recipe == "movi_f":  # the line docs/renderers.md shows
        assert f"kubric worker: error: {err.value}\n" in (ROOT / "docs" / "renderers.md").read_text()
    get_recipe(recipe).from_assignments(["renderer=blender", *options])  # the backend that can


def test_the_command_line_refusal_is_one_line(tmp_path):
    proc = kubric("worker", "complex_brdf", "--seed", 1, "--out", tmp_path, "--set",
                  "renderer=raycast")
    assert proc.returncode == 2 and proc.stderr.count("\n") == 1, proc.stderr
    assert proc.stderr == ("kubric worker: error: complex_brdf: renderer=raycast cannot render "
                           "photoreal RGB (the complex_brdf recipe); backends that can: "
                           "blender\n")
    assert not list(tmp_path.iterdir())


# ------------------------------------------------------------------------------ tiny scenes
def _worker(recipe, out, *options):
    args = ["worker", recipe, "--seed", 2, "--out", out, "--set", "renderer=raycast"]
    for option in options:
        args += ["--set", option]
    proc = kubric(*args)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    scene = out / "scene_00000002"
    meta = json.loads((scene / "metadata.json").read_text())
    assert meta["metadata"]["renderer"]["engine"] == "RAYCAST"
    assert meta["flags"]["renderer"] == "raycast"
    assert "quality" not in meta["metadata"]["renderer"]  # no quality profile without Cycles
    return scene, meta


def test_klevr_with_raycast_and_its_nerf_export(tmp_path):
    """A multi-view scene without bpy; ``kubric export nerf`` copies exactly the transforms
    files and the files their views name, and the rays, RGB and depth read back from the
    export are the scene's, view by view (RGB and depth read from the scene's own files)."""
    scene, meta = _worker("klevr", tmp_path / "scenes", "resolution=24x16", "num_views=3",
                          "split_ratio=1,1,1", "min_num_objects=3", "max_num_objects=4")
    out = tmp_path / "nerf"
    proc = kubric("export", "nerf", tmp_path / "scenes", "--out", out)
    assert proc.returncode == 0, proc.stderr
    exported = out / scene.name
    named = {f"transforms_{s}.json" for s in nerf.SPLITS}
    for split in nerf.SPLITS:
        for entry in json.loads((scene / f"transforms_{split}.json").read_text())["frames"]:
            named |= {entry["file_path"][2:] + ".png"} | {v for k, v in entry.items()
                                                          if k.endswith("_file")}
    assert {p.name for p in exported.iterdir()} == named
    assert "metadata.json" not in named and "depth_00002.tiff" in named
    views = 0
    for split in nerf.SPLITS:
        for ours, theirs in zip(nerf.iter_views(exported, split), nerf.iter_views(scene, split),
                                strict=True):
            i = ours["view"]
            np.testing.assert_array_equal(ours["rgb"], png_io.read_png(
                scene / f"rgba_{i:05d}.png")[..., :3])
            np.testing.assert_array_equal(ours["depth"], tiff_io.read_tiff(
                scene / f"depth_{i:05d}.tiff")[..., 0])
            np.testing.assert_array_equal(ours["directions"], theirs["directions"])
            views += 1
    assert views == 3 == len(meta["metadata"]["views"])
    again = kubric("export", "nerf", tmp_path / "scenes", "--out", out)
    assert again.returncode == 2 and again.stderr.count("\n") == 1
    assert "already exists" in again.stderr


def test_vbr_with_raycast_writes_its_lasr_sequence(tmp_path):
    """A video recipe without bpy; not a multi-view scene, so the NeRF export writes one
    ``transforms.json`` of its frames (tests/test_rig_nerf_lasr.py checks its geometry)."""
    scene, meta = _worker("vbr", tmp_path, "resolution=24", "num_frames=3")
    lasr = json.loads((scene / "lasr" / "export.json").read_text())
    assert lasr["num_frames"] == 3 and lasr["sequence"] == meta["metadata"]["lasr_sequence"]
    proc = kubric("export", "nerf", scene, "--out", tmp_path / "nerf")
    assert proc.returncode == 0, proc.stderr[-2000:]
    data = json.loads((tmp_path / "nerf" / scene.name / "transforms.json").read_text())
    assert [(f["camera"], f["frame"], f["time"]) for f in data["frames"]] == \
        [(0, 0, 0.0), (0, 1, 0.5), (0, 2, 1.0)]
    assert [f["file_path"] for f in data["frames"]] == [f"./rgba_{t:05d}.png" for t in range(3)]
    assert sorted(p.name for p in (tmp_path / "nerf" / scene.name).iterdir()) == sorted(
        ["transforms.json"] + [f"{layer}_{t:05d}.{ext}" for t in range(3) for layer, ext in
                               (("rgba", "png"), ("depth", "tiff"), ("segmentation", "png"))])


def test_svr_with_raycast_has_a_transparent_film(tmp_path):
    """svr asks its backend for a transparent film: with raycast, alpha is 0 exactly where the
    segmentation sees no object and 255 on the object."""
    from kubric import file_io

    scene, _ = _worker("svr", tmp_path, "resolution=24x16", "num_views=3", "split_ratio=1,1,1")
    layers = file_io.read_image_dict(scene)
    alpha, seg = layers["rgba"][..., 3], layers["segmentation"][..., 0]
    assert 0 < (seg > 0).mean() < 1
    assert set(np.unique(alpha[seg == 0])) == {0} and set(np.unique(alpha[seg > 0])) == {255}

"""The call patterns of upstream Kubric's own scripts that issue #24 found failing here.

Each test performs the call the way an upstream worker or example does (described in the test)
and checks the outcome on real output: files read back, Blender's own data, PyBullet's state.
"""

import copy
import inspect
import pathlib
import pickle
import warnings

import numpy as np
import pytest

import kubric as kb
from kubric import file_io, randomness
from kubric.core import objects as core_objects
from kubric.core import rng as rng_policy
from kubric.pipeline import get_recipe
from kubric.pipeline.worker import run_scene


# ------------------------------------------------------------------ unseeded default generator
def _no_worker_rng():
    assert randomness.worker_rng() is None  # no kb.setup rng held by this test


def test_upstream_defaulted_functions_run_without_rng_and_warn_once():
    """examples/simulator.py calls resample_while without rng, examples/keyframing.py
    get_clevr_lights(); both had an unseeded default generator upstream."""
    _no_worker_rng()
    rng_policy._warned.clear()
    cube = kb.Cube(scale=0.2)
    with pytest.warns(randomness.UnseededRandomnessWarning, match="resample_while"):
        trials = kb.resample_while(cube, [kb.position_sampler([[-1, -1, 0], [1, 1, 1]])],
                                   condition=lambda obj: obj.position[2] < 0.5)
    assert trials >= 1 and cube.position[2] >= 0.5 - 1e-6
    with pytest.warns(randomness.UnseededRandomnessWarning, match="get_clevr_lights"):
        lights = kb.assets.utils.get_clevr_lights()
    base = [np.asarray(position) for *_, position in kb.assets.clevr.LIGHTS]
    for light, position in zip(lights, base, strict=True):
        jitter = np.asarray(light.position) - position
        assert np.all(jitter >= -1e-6) and np.all(jitter <= 1 + 1e-6)  # U[0, 1)³ · 1 m
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the second call of the same function does not warn
        kb.assets.utils.get_clevr_lights()


def test_unseeded_results_differ_between_calls_and_default_rng_is_fresh():
    """Not reproducible, as documented: two unseeded draws differ; default_rng() is upstream's
    fresh RandomState (complex_brdf's worker calls it to build a default argument)."""
    _no_worker_rng()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", randomness.UnseededRandomnessWarning)
        draws = {kb.random_hue_color() for _ in range(4)}
        points = {tuple(kb.sample_point_in_half_sphere_shell(1.0, 2.0)) for _ in range(4)}
    assert len(draws) == 4 and len(points) == 4
    a, b = randomness.default_rng(), randomness.default_rng()
    assert isinstance(a, np.random.RandomState) and a is not b
    assert a.uniform(size=4).tolist() != b.uniform(size=4).tolist()


def test_functions_upstream_never_defaulted_still_need_rng():
    _no_worker_rng()
    with pytest.raises(TypeError, match="random_clevr_color needs rng="):
        randomness.random_clevr_color()
    defaulted = {name for name, fn in inspect.getmembers(randomness, inspect.isfunction)
                 if "rng" in inspect.signature(fn).parameters
                 and fn.__module__ == randomness.__name__} & randomness.UPSTREAM_DEFAULTED
    # every listed name (but the one in kb.assets.utils) is a function of this module with rng=
    assert defaulted == randomness.UPSTREAM_DEFAULTED - {"kb.assets.utils.get_clevr_lights"}


def test_explicit_rng_only_names_the_function_and_the_run():
    with randomness.explicit_rng_only("recipe 'x'"):
        with pytest.raises(RuntimeError, match=r"move_until_no_overlap .*explicit rng inside "
                                               r"recipe 'x'"):
            kb.move_until_no_overlap(kb.Cube(), simulator=None)
        with pytest.raises(RuntimeError, match=r"default_rng\(\) .* inside recipe 'x'"):
            randomness.default_rng()
        # an explicit rng is fine
        assert isinstance(kb.random_hue_color(rng=np.random.RandomState(0)), kb.Color)
        # rng=None is refused even while a kb.setup rng is bound: recipes pass theirs
        worker = randomness.WorkerRandomState(0)
        randomness.bind_worker_rng(worker)
        with pytest.raises(RuntimeError, match="random_clevr_color was called without an "
                                               "explicit rng inside recipe 'x'"):
            randomness.random_clevr_color()
        del worker
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", randomness.UnseededRandomnessWarning)
        kb.random_hue_color()  # allowed again outside the block


class _CarelessRecipe:
    """A recipe whose generate() forgets rng= (what run_scene must refuse)."""

    name = "careless"

    def generate(self, seed, out_dir):
        (pathlib.Path(out_dir) / "color.txt").write_text(str(kb.random_hue_color()))


def test_run_scene_refuses_a_recipe_that_omits_rng(tmp_path):
    with pytest.raises(RuntimeError, match="random_hue_color .* inside recipe 'careless'"):
        run_scene(_CarelessRecipe(), 0, tmp_path)
    assert not list(tmp_path.iterdir())  # nothing partial left behind


@pytest.mark.parametrize("name, options", [
    ("movi_a", ["min_num_objects=3", "max_num_objects=4"]),
    ("movi_b", ["min_num_objects=3", "max_num_objects=4"]),
    ("movi_e", ["min_num_objects=3", "max_num_objects=4", "settle_frames=5",
                "collection_limit=8", "articulated_objects=1"]),
])
def test_movi_scenes_set_every_friction_and_never_reach_the_unseeded_generator(
        name, options, monkeypatch, tmp_path):
    """Populate (place, settle) MOVi scenes with the class's friction default replaced by a
    sentinel: no object keeps it, so the 0 → 0.5 default change leaves MOVi's recorded frictions
    alone — except articulated link parts, which carry no physics of their own (PyBullet applies
    the base's friction to every link) and now record the default 0.5 instead of 0."""
    recipe = get_recipe(name).from_assignments(options)
    recipe.prepare()
    sources = recipe.open_sources()
    sentinel = 0.123
    monkeypatch.setattr(core_objects.PhysicalObject.__dict__["friction"], "default", sentinel)
    assert kb.Cube().friction == sentinel
    for seed in range(2):
        scene = recipe.make_scene()
        simulator = kb.simulator.PyBullet(scene, tmp_path / f"scratch{seed}")
        try:
            with randomness.explicit_rng_only(f"recipe {name!r}"):
                recipe.populate(scene, simulator, np.random.RandomState(seed), sources)
        finally:
            simulator.close()
        physical = [a for a in scene.assets if isinstance(a, kb.PhysicalObject)]
        assert len(physical) >= 4  # the dome and at least three objects
        links = [a for a in physical if "articulated_link" in a.metadata]
        assert bool(links) == (name == "movi_e"), name
        for obj in physical:
            if obj in links:
                assert obj.friction == sentinel  # the default: recorded, unused by PyBullet
            else:
                assert obj.friction != sentinel, (name, seed, obj.uid)


def test_physical_object_friction_default_is_upstreams():
    assert kb.PhysicalObject().friction == 0.5
    assert kb.Cube().friction == kb.Sphere().friction == kb.FileBasedObject().friction == 0.5


def test_light_defaults_are_upstreams():
    """Upstream's code: lights are background assets; SpotLight.spot_blend = 1."""
    scene = kb.Scene()
    cube = kb.Cube()
    scene += [kb.DirectionalLight(), kb.PointLight(), kb.RectAreaLight(), kb.SpotLight(), cube]
    assert all(light.background for light in scene.assets if isinstance(light, kb.Light))
    assert scene.foreground_assets == (cube,)
    assert kb.SpotLight().spot_blend == 1.0 and kb.SpotLight().spot_size == pytest.approx(np.pi / 4)


# ------------------------------------------------------------------ pickling
def _value_types():
    """Every public value type, one instance each, with a non-default value."""
    scene = kb.Scene(resolution=(8, 6), frame_end=2)
    cube = kb.Cube(name="box", position=(1, 2, 3), quaternion=kb.Quaternion(axis=[0, 0, 1],
                                                                             degrees=30),
                   material=kb.PrincipledBSDFMaterial(color=kb.Color(0.9, 0.1, 0.2, 0.5)))
    cube.metadata = {"color": kb.Color(1, 1, 1), "size": 1.4, "shape": "cube"}
    scene += cube
    scene.camera = kb.PerspectiveCamera(position=(0, -5, 2), look_at=(0, 0, 0))
    return {
        "Color": kb.Color(0.25, 0.5, 0.75, 0.125),
        "Color (named)": kb.get_color("red"),
        "Quaternion": kb.Quaternion(axis=[1, 0, 0], degrees=90),
        "vector (read-only float32)": cube.position,
        "quaternion property": cube.quaternion,
        "asset metadata": cube.metadata,
        "scene metadata": kb.get_scene_metadata(scene),
        "camera info": kb.get_camera_info(scene.camera),
        "instance info": kb.get_instance_info(scene, [cube]),
        "layer format": file_io.LAYERS["forward_flow"],
    }


def _same(a, b):
    if isinstance(a, dict):
        return isinstance(b, dict) and a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    if isinstance(a, (list, tuple)) and not isinstance(a, kb.Color):
        return type(a) is type(b) and len(a) == len(b) and all(map(_same, a, b))
    if isinstance(a, np.ndarray):
        return isinstance(b, np.ndarray) and a.dtype == b.dtype and np.array_equal(a, b)
    return type(a) is type(b) and a == b


@pytest.mark.parametrize("protocol", [2, pickle.DEFAULT_PROTOCOL, pickle.HIGHEST_PROTOCOL])
def test_every_public_value_type_round_trips_through_pickle_and_copy(protocol, tmp_path):
    for label, value in _value_types().items():
        back = pickle.loads(pickle.dumps(value, protocol=protocol))
        assert _same(value, back), label
        assert _same(value, copy.deepcopy(value)) and _same(value, copy.copy(value)), label
    # robust_nerf's worker: kb.write_pkl of metadata holding a Color, read back
    data = {"background": {"background_color": kb.Color(0.1, 0.2, 0.3),
                           "floor_color": kb.get_color("gray").rgb}}
    file_io.write_pkl(data, tmp_path / "metadata.pkl")
    back = file_io.read_pkl(tmp_path / "metadata.pkl")
    assert back == data and isinstance(back["background"]["background_color"], kb.Color)
    assert tuple(back["background"]["background_color"]) == (0.1, 0.2, 0.3, 1.0)


def test_assets_and_scenes_refuse_pickling_with_one_clear_line():
    for entity, name in ((kb.Cube(name="box"), "Cube 'box'"), (kb.Scene(), "Scene")):
        for attempt in (pickle.dumps, copy.deepcopy, copy.copy):
            with pytest.raises(TypeError, match=rf"^{name} cannot be pickled or copied .*"
                                                r"kb.get_instance_info"):
                attempt(entity)


# ------------------------------------------------------------------ batch writers
def test_multi_write_image_with_a_palette_and_write_png(tmp_path):
    """video_based_reconstruction/worker.py: multi_write_image(segmentation, "<dir>/{:05d}.png",
    write_fn=kb.write_palette_png, max_write_threads=16, palette=[[r, g, b], ...]) and with
    write_fn=kb.write_png for the RGBA frames."""
    labels = np.zeros((3, 5, 7, 1), np.uint32)
    labels[:, 1:3, 2:6] = 2
    labels[1, 4, :] = 1
    palette = [[0, 0, 0], [0, 0, 0], [128, 128, 128]]
    paths = kb.file_io.multi_write_image(labels, str(tmp_path / "ann" / "{:05d}.png"),
                                         write_fn=kb.write_palette_png, max_write_threads=16,
                                         palette=palette)
    assert [pathlib.Path(p).name for p in paths] == ["00000.png", "00001.png", "00002.png"]
    for i, path in enumerate(paths):
        back, stored_palette = kb.read_palette_png(path, return_palette=True)
        np.testing.assert_array_equal(back, labels[i])
        np.testing.assert_array_equal(stored_palette[:3], palette)
    rgba = np.random.RandomState(0).randint(0, 256, (2, 5, 7, 4)).astype(np.uint8)
    kb.file_io.multi_write_image(rgba, str(tmp_path / "rgb" / "{:05d}.png"), write_fn=kb.write_png,
                                 max_write_threads=16)
    for i in range(2):
        np.testing.assert_array_equal(kb.read_png(tmp_path / "rgb" / f"{i:05d}.png"), rgba[i])
    with pytest.raises(ValueError, match="max_write_threads must be an int ≥ 1"):
        kb.file_io.multi_write_image(rgba, str(tmp_path / "{:05d}.png"), max_write_threads=0)
    with pytest.raises(ValueError, match="holds no images"):
        kb.file_io.multi_write_image(rgba[:0], str(tmp_path / "{:05d}.png"))


def test_write_flow_batch_with_name_keys_its_range_and_decodes(tmp_path):
    """video_based_reconstruction/worker.py writes forward and backward flow into folders of
    their own with file_template="{:05d}.png" and name="forward_flow" / "backward_flow"."""
    rng = np.random.RandomState(1)
    forward = rng.normal(0, 3, (4, 6, 5, 2)).astype(np.float32)
    backward = rng.normal(0, 2, (4, 6, 5, 2)).astype(np.float32)
    kb.file_io.write_flow_batch(forward, directory=tmp_path / "FlowFW", file_template="{:05d}.png",
                                name="forward_flow", max_write_threads=16)
    kb.file_io.write_flow_batch(backward, directory=tmp_path / "FlowFW", file_template="b{:05d}.png",
                                name="backward_flow", max_write_threads=16)
    ranges = kb.read_json(tmp_path / "FlowFW" / "data_ranges.json")
    assert set(ranges) == {"forward_flow", "backward_flow"}  # merged, each under its name
    assert ranges["forward_flow"] == {"min": float(forward.min()), "max": float(forward.max())}
    for prefix, flow, key in (("", forward, "forward_flow"), ("b", backward, "backward_flow")):
        lo, hi = ranges[key]["min"], ranges[key]["max"]
        for t in range(4):
            raw = kb.read_png(tmp_path / "FlowFW" / f"{prefix}{t:05d}.png")
            assert raw.dtype == np.uint16 and raw.shape == (6, 5, 3) and not raw[..., 2].any()
            decoded = raw[..., :2] / 65535 * (hi - lo) + lo  # nearest of the 65536 levels
            assert np.abs(decoded - flow[t]).max() <= 0.5 * (hi - lo) / 65535 * (1 + 1e-5)
    # upstream's named partials keep their own templates and names
    kb.file_io.write_backward_flow_batch(backward, tmp_path / "scene")
    assert (tmp_path / "scene" / "backward_flow_00003.png").is_file()
    back = kb.read_layer(tmp_path / "scene", "backward_flow")
    np.testing.assert_allclose(back, backward, atol=(backward.max() - backward.min()) / 65535)
    with pytest.raises(ValueError, match=r"shape \(T, H, W, 2\)"):
        kb.file_io.write_flow_batch(forward[..., :1], tmp_path, name="x")
    with pytest.raises(ValueError, match="name must be a non-empty str"):
        kb.file_io.write_flow_batch(forward, tmp_path, name="")


# ------------------------------------------------------------------ observers
def test_observe_reports_changes_and_keyframes_like_upstreams_traitlets():
    """Upstream assets were traitlets objects: obj.observe(handler, "position",
    type="keyframe") got one change per keyframe_insert with name, owner, frame and type."""
    obj = kb.Cube()
    changes, keys, everything = [], [], []
    obj.observe(changes.append, "position")
    obj.observe(keys.append, ["position"], type="keyframe")
    obj.observe(everything.append)
    obj.position = (3, 3, 3)
    obj.keyframe_insert("position", 7)
    obj.scale = 2
    obj.keyframe_insert("scale", 2)
    assert [(c.name, c.type) for c in changes] == [("position", "change")]
    np.testing.assert_array_equal(changes[0].old, (0, 0, 0))
    np.testing.assert_array_equal(changes[0].new, (3, 3, 3))
    assert changes[0].owner is obj
    assert [(k.name, k.owner, k.frame, k.type) for k in keys] == [("position", obj, 7, "keyframe")]
    assert [c.name for c in everything] == ["position", "scale"]
    obj.unobserve(changes.append, "position")
    obj.position = (1, 1, 1)
    assert len(changes) == 1 and len(everything) == 3
    with pytest.raises(KeyError, match="doesnotexist"):
        obj.observe(changes.append, "doesnotexist")
    with pytest.raises(ValueError, match="type must be 'change' or 'keyframe'"):
        obj.observe(changes.append, "position", type="other")

"""Upstream-Kubric behaviour kept for scripts written against upstream (README "Compatibility").

Each test checks one behaviour on real output (a written file read back, Blender's own state, a
rotation applied to a vector) against an independent derivation.
"""

import itertools
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import kubric as kb
from kubric import file_io
from kubric.core import objects
from kubric.core.view import View
from kubric.renderer import blender_utils


# ------------------------------------------------------------------------------------ colours
def test_hexstr_short_is_one_digit_per_channel_and_inverts_short_strings():
    digits = "0123456789abcdef"
    for r, g, b in itertools.product(digits, repeat=3):
        assert kb.Color.from_hexstr(f"#{r}{g}{b}").hexstr_short == f"#{r}{g}{b}f"
    for short in ("#0000", "#f0c8", "#1a2b", "#ffff"):
        assert kb.Color.from_hexstr(short).hexstr_short == short
    # a channel between two levels goes to the nearer one: 0.2 * 15 = 3, 0.5 * 15 = 7.5 -> 8
    assert kb.Color(0.2, 0.5, 1.0, 0.0).hexstr_short == "#38f0"


def test_short_hex_strings_expand_each_digit():
    assert kb.get_color("#f0f").rgb == (1.0, 0.0, 1.0)
    assert kb.get_color("#f0f8") == kb.Color(1.0, 0.0, 1.0, 0x88 / 255)
    with pytest.raises(ValueError, match="3, 4, 6 or 8 hex digits"):
        kb.Color.from_hexstr("#12345")


# ------------------------------------------------------------------------------------ assets
def test_unknown_constructor_argument_is_a_key_error_and_a_type_error():
    with pytest.raises(KeyError) as info:
        kb.Cube(doesnotexist=1)
    assert isinstance(info.value, TypeError)
    message = str(info.value)
    assert "'doesnotexist'" in message and "allowed:" in message
    assert not message.startswith('"')  # shown as written, not quoted like a bare KeyError
    # upstream's Object3D takes `position`, not Blender's `location`
    with pytest.raises(KeyError, match="location"):
        objects.Object3D(location=(1, 2, 3))
    with pytest.raises(KeyError, match="no property 'doesnotexist'"):
        kb.Cube().keyframe_insert("doesnotexist", 1)


def test_asset_repr_is_uid_then_sorted_properties_on_one_line():
    scene = kb.Scene()
    scene += kb.Cube(name="box")
    mat = kb.FlatMaterial(name="paint")
    box = kb.Cube(name="box", position=(1, 2, 3), material=mat)
    scene += box  # uids are numbered by the scene
    text = repr(box)
    assert text.startswith("<box.001 ") and text.endswith(">") and "\n" not in text
    fields = text[len("<box.001 "):-1].split(" ")
    keys = [f.split("=", 1)[0] for f in fields if "=" in f]
    assert keys == sorted(keys)
    assert set(keys) == {"name", *kb.Cube.property_names()}
    assert "name='box'" in fields
    assert "position=[1.0, 2.0, 3.0]" in text
    assert "material=<paint>" in fields  # a held asset is shown by its uid only
    assert repr(kb.Asset()).startswith("<Asset background=False metadata={} name='Asset'")


def _rotate(q, v):
    """v rotated by the unit WXYZ quaternion q, via q v q* written out in components."""
    w, x, y, z = q
    u = np.array([x, y, z])
    v = np.asarray(v, dtype=np.float64)
    return v + 2.0 * np.cross(u, np.cross(u, v) + w * v)


@pytest.mark.parametrize("position, target, up, front", [
    ((0, 0, 0), (1, 1, 1), "Y", "-Z"),
    ((1, -2, 0.5), (-3, 0, 2), "Y", "-Z"),
    ((0, 0, 0), (2, 0, 1), "Z", "X"),
    ((0, 0, 0), (0, 3, -1), (0, 1, 0), (0, 0, -1)),
])
def test_look_at_quat_points_front_at_target_with_up_towards_world_z(position, target, up, front):
    q = objects.look_at_quat(position, target, up, front)
    assert isinstance(q, tuple) and len(q) == 4 and all(isinstance(c, float) for c in q)
    front_v = kb.core.quaternion.axis_vector(front)
    up_v = kb.core.quaternion.axis_vector(up)
    direction = np.subtract(target, position, dtype=np.float64)
    direction /= np.linalg.norm(direction)
    np.testing.assert_allclose(_rotate(q, front_v), direction, atol=1e-9)
    # the rotated up axis is world +Z with its component along the view direction removed
    expected_up = np.array([0.0, 0.0, 1.0]) - direction[2] * direction
    expected_up /= np.linalg.norm(expected_up)
    np.testing.assert_allclose(_rotate(q, up_v), expected_up, atol=1e-9)


# ------------------------------------------------------------------------------------ views
class _RecordingView(View):
    def __init__(self, scene):
        self.calls = []
        super().__init__(scene)

    def add_scene(self, scene):
        self.calls.append(("add_scene", scene))

    def add(self, item):
        self.calls.append(("add", item))


def test_view_module_path_and_views_receive_assets_only_through_add():
    from kubric.core import view, views
    assert view.View is views.View and view.TableView is views.TableView
    scene = kb.Scene()
    cube = kb.Cube()
    scene.add(cube)
    recorder = _RecordingView(scene)
    sphere = kb.Sphere()
    scene.add(sphere)
    scene.add(sphere)  # twice: still one call
    assert recorder.calls == [("add_scene", scene), ("add", cube), ("add", sphere)]


# ------------------------------------------------------------------------------------ file io
def test_write_image_dict_stores_quantised_uv_and_normal_as_given(tmp_path):
    rng = np.random.default_rng(0)
    uv8 = rng.integers(0, 256, (2, 4, 5, 3), dtype=np.uint8)
    normal8 = rng.integers(0, 256, (2, 4, 5, 3), dtype=np.uint8)
    coords16 = rng.integers(0, 65536, (2, 4, 5, 3), dtype=np.uint16)
    ranges = file_io.write_image_dict(
        {"uv": uv8, "normal": normal8, "object_coordinates": coords16}, tmp_path)
    assert ranges == {}
    for i in range(2):
        np.testing.assert_array_equal(file_io.read_png(tmp_path / f"uv_{i:05d}.png"), uv8[i])
        np.testing.assert_array_equal(file_io.read_png(tmp_path / f"normal_{i:05d}.png"),
                                      normal8[i])
        assert file_io.read_png(tmp_path / f"uv_{i:05d}.png").dtype == np.uint8
        np.testing.assert_array_equal(
            file_io.read_png(tmp_path / f"object_coordinates_{i:05d}.png"), coords16[i])
    back = file_io.read_image_dict(tmp_path)
    np.testing.assert_allclose(back["uv"], uv8 / 255.0, atol=1e-7)
    np.testing.assert_allclose(back["normal"], normal8 / 255.0 * 2.0 - 1.0, atol=1e-6)
    np.testing.assert_allclose(back["object_coordinates"], coords16 / 65535.0, atol=1e-7)


def test_write_image_dict_still_rejects_other_integer_layers(tmp_path):
    with pytest.raises(TypeError, match="layer 'uv'.*int32"):
        file_io.write_image_dict({"uv": np.zeros((1, 2, 2, 3), np.int32)}, tmp_path)
    assert not any(tmp_path.iterdir())


# ------------------------------------------------------------------------------------ blender utils
def test_murmurhash3_matches_published_vectors():
    # MurmurHash3_x86_32 reference vectors (SMHasher)
    assert blender_utils.murmurhash3_32(b"", 0) == 0
    assert blender_utils.murmurhash3_32(b"", 1) == 0x514E28B7
    assert blender_utils.murmurhash3_32(b"", 0xFFFFFFFF) == 0x81F16F39
    assert blender_utils.murmurhash3_32(b"\x00\x00\x00\x00", 0) == 0x2362F9DE
    assert blender_utils.murmurhash3_32(b"aaaa", 0x9747B28C) == 0x5A97808A
    assert blender_utils.murmurhash3_32(b"abc", 0) == 0xB3DD93FA
    assert blender_utils.murmurhash3_32(b"Hello, world!", 1234) == 0xFAF6CDB3
    assert blender_utils.murmurhash3_32(
        b"The quick brown fox jumps over the lazy dog", 0x9747B28C) == 0x2FA826CD


def test_mm3hash_is_cryptomatte_id():
    # ids Blender's Cryptomatte pass gives these object names
    assert blender_utils.mm3hash("Static") == 3498399415
    assert blender_utils.mm3hash("Object_00") == 991243257
    assert blender_utils.mm3hash("Object_41") == 12644183
    # the float32 exponent of an id is never 0 (denormal) or 255 (inf / NaN)
    flipped = 0
    for i in range(3000):
        name = f"n{i}"
        raw = blender_utils.murmurhash3_32(name.encode())
        h = blender_utils.mm3hash(name)
        assert ((h >> 23) & 0xFF) not in (0, 255)
        if ((raw >> 23) & 0xFF) in (0, 255):
            flipped += 1
            assert h == raw ^ (1 << 23)
        else:
            assert h == raw
    assert flipped > 0  # ~2/256 of names need the flip


def test_upstream_module_paths_import_no_engine():
    code = ("import sys; import kubric.renderer.blender_utils, kubric.core.view, "
            "kubric.safeimport; assert 'bpy' not in sys.modules, 'bpy imported'")
    subprocess.run([sys.executable, "-c", code], check=True)


@pytest.mark.blender
def test_prepare_blender_object_names_links_and_sets_quaternion_mode():
    from kubric.safeimport.bpy import bpy
    bpy.ops.wm.read_factory_settings()  # the startup file: it holds an object named "Cube"
    assert "Cube" in bpy.data.objects

    @blender_utils.prepare_blender_object
    def add_asset(view, asset):
        mesh = bpy.data.meshes.new("m")
        return bpy.data.objects.new("whatever", mesh)

    cube = kb.Cube()
    obj = add_asset(None, cube)
    assert obj.name == cube.uid == "Cube"
    assert obj.rotation_mode == "QUATERNION"
    assert obj in bpy.context.scene.collection.objects.values()
    assert "Cube.001" in bpy.data.objects  # the older object gave up the name


@pytest.mark.blender
def test_blender_options_set_after_construction_reach_cycles(tmp_path):
    from kubric.renderer.blender import Blender
    renderer = Blender(kb.Scene(resolution=(4, 4)), tmp_path, samples_per_pixel=3,
                       use_denoising=False)
    assert renderer.blender_scene is renderer.bpy_scene
    cycles = renderer.blender_scene.cycles
    assert (cycles.samples, cycles.use_denoising, cycles.use_adaptive_sampling) == (3, False, False)
    renderer.samples_per_pixel = 7
    renderer.adaptive_sampling = True
    renderer.use_denoising = True
    renderer.background_transparency = True
    assert (cycles.samples, cycles.use_adaptive_sampling, cycles.use_denoising) == (7, True, True)
    assert renderer.blender_scene.render.film_transparent is True
    with pytest.raises(ValueError, match="samples_per_pixel must be an integer ≥ 1"):
        renderer.samples_per_pixel = 0
    assert cycles.samples == 7 and renderer.samples_per_pixel == 7


# ------------------------------------------------------------------------------------ the count
def test_run_upstream_tests_counts_passes_failures_and_unimportable_modules(tmp_path):
    """tools/run_upstream_tests.py on a small stand-in for upstream's test folder."""
    tests = tmp_path / "test"
    tests.mkdir()
    (tests / "__init__.py").write_text("")
    (tests / "test_ok.py").write_text(
        "import pytest\nfrom kubric.core import color\n\n"
        "def test_short():\n    assert color.Color.from_hexstr('#f0c').hexstr_short == '#f0cf'\n\n"
        "def test_wrong():\n    assert color.get_color('red').rgb == (0, 1, 0)\n\n"
        "@pytest.mark.skip\ndef test_skipped():\n    pass\n")
    (tests / "test_broken.py").write_text(
        "import pytest\nimport a_module_nobody_has\n\n"
        "@pytest.mark.parametrize('x', [1, 2, 3])\ndef test_a(x):\n    pass\n\n"
        "class TestB:\n    def test_b(self):\n        pass\n")
    script = Path(__file__).parents[1] / "tools" / "run_upstream_tests.py"
    out = subprocess.run([sys.executable, str(script), str(tmp_path)], capture_output=True,
                         text=True, check=True).stdout.splitlines()
    assert "failed   test.test_ok::test_wrong" in out
    assert ("import   test_broken.py: 4 tests not collected "
            "(ModuleNotFoundError: No module named 'a_module_nobody_has')") in out
    assert out[-2] == "collected 3: 1 passed, 1 failed, 1 skipped"
    assert out[-1] == "upstream tests: 1 of 7 passed"


def test_physical_object_defaults_are_upstreams_and_reach_pybullet():
    """Upstream's PhysicalObject defaults (its code, kubric/core/objects.py at HEAD): mass 1,
    friction 0.5, restitution 0.5, not static; the simulator body gets the same friction
    (PyBullet's getDynamicsInfo does not report the restitution it uses; the bounce tests in
    test_simulator.py cover restitution)."""
    import pybullet as pb

    scene = kb.Scene()
    simulator = kb.simulator.PyBullet(scene)
    cube = kb.Cube(position=(0, 0, 1))
    assert (cube.mass, cube.friction, cube.restitution, cube.static) == (1.0, 0.5, 0.5, False)
    scene += cube
    info = pb.getDynamicsInfo(simulator._body_of(cube).uid, -1, physicsClientId=simulator.client)
    assert (info[0], info[1]) == (1.0, 0.5)  # mass, lateral friction
    simulator.close()

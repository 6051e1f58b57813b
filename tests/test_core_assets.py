"""Scene model: construction, validation, uids, notifications, keyframes."""

import numpy as np
import pytest

import kubric as kb
from kubric.core.views import TableView, View


class RecordingView(View):
    """A view that records every call it receives."""

    def __init__(self, scene):
        self.calls = []
        super().__init__(scene)

    def add(self, item):
        self.calls.append(("add", item))

    def remove(self, asset):
        self.calls.append(("remove", asset))

    def on_change(self, item, name, value):
        self.calls.append(("change", item, name))

    def on_keyframe(self, asset, name, frame):
        self.calls.append(("keyframe", asset, name, frame))

    def on_keyframe_delete(self, asset, name, frame):
        self.calls.append(("keyframe_delete", asset, name, frame))


def test_uids_are_numbered_per_scene_in_joining_order():
    a, b, c = kb.Cube(), kb.Cube(), kb.Cube(name="floor")
    assert a.uid == b.uid == "Cube" and a != b and len({a, b}) == 2  # in no scene: the name
    scene = kb.Scene()
    scene.add([b, a, c])
    assert (b.uid, a.uid, c.uid) == ("Cube", "Cube.001", "floor")
    assert kb.UndefinedMaterial().uid == kb.UndefinedMaterial().uid == "UndefinedMaterial"
    # materials that come along are numbered too
    mats = [kb.PhysicalObject(material=kb.FlatMaterial()) for _ in range(2)]
    scene.add(mats)
    assert [m.uid for m in mats] == ["PhysicalObject", "PhysicalObject.001"]
    assert [m.material.uid for m in mats] == ["FlatMaterial", "FlatMaterial.001"]
    # another scene counts afresh: nothing global, nothing to reset
    other = kb.Scene()
    d = kb.Cube()
    other += d
    assert d.uid == "Cube" and d != b
    # an asset keeps the uid of its first scene; a clash in a later scene names the uid
    other += a
    assert a.uid == "Cube.001" and a in other.assets
    e = kb.Cube()
    other += e
    assert e.uid == "Cube.002"
    with pytest.raises(ValueError, match="this scene already has another asset with uid 'Cube'"):
        other += b
    # a removed asset's number is not given again
    scene.remove(a)
    f = kb.Cube()
    scene += f
    assert f.uid == "Cube.002" and a.uid == "Cube.001"


def test_a_scene_built_twice_has_the_same_uids():
    def build():
        scene = kb.Scene(camera=kb.PerspectiveCamera())
        scene += [kb.Sphere(), kb.Cube(), kb.Sphere(name="ball"), kb.Sphere()]
        scene += kb.DirectionalLight()
        return [x.uid for x in scene.assets]

    first = build()
    kb.Cube(), kb.Sphere()  # assets made in between change nothing
    assert build() == first == ["PerspectiveCamera", "Sphere", "Cube", "ball", "Sphere.001",
                                "DirectionalLight"]


def test_unknown_keyword_is_rejected_naming_it():
    with pytest.raises(TypeError, match=r"unknown argument\(s\) \['colour'\]"):
        kb.Cube(colour="red")


@pytest.mark.parametrize("kwargs, fragment", [
    ({"mass": -1}, r"Cube.mass must be in \[0, inf\], got -1"),
    ({"friction": 1.5}, r"Cube.friction must be in \[0, 1\], got 1.5"),
    ({"restitution": -0.1}, r"Cube.restitution must be in \[0, 1\], got -0.1"),
    ({"bounds": ((1, 0, 0), (0, 1, 1))}, r"lower bound \[1.0, 0.0, 0.0\] exceeds upper"),
    ({"position": (1, 2)}, r"Cube.position must be 3 finite numbers"),
    ({"quaternion": (0, 0, 0, 0)}, r"Cube.quaternion must be a non-zero WXYZ quaternion"),
    ({"static": "yes"}, r"Cube.static must be True or False"),
])
def test_bad_values_name_property_value_and_allowed_range(kwargs, fragment):
    with pytest.raises((ValueError, TypeError), match=fragment):
        kb.Cube(**kwargs)


def test_live_assignment_is_validated_and_value_kept():
    cube = kb.Cube(mass=2.0)
    with pytest.raises(ValueError, match="mass"):
        cube.mass = -1
    assert cube.mass == 2.0


def test_vectors_are_read_only_float32_and_scale_broadcasts():
    cube = kb.Cube(position=(1, 2, 3), scale=2)
    assert cube.position.dtype == np.float32 and cube.scale.tolist() == [2.0, 2.0, 2.0]
    with pytest.raises(ValueError):
        cube.position[0] = 5.0
    assert cube.quaternion.dtype == np.float32 and cube.quaternion.tolist() == [1, 0, 0, 0]


def test_look_at_and_euler_shortcuts():
    cam = kb.PerspectiveCamera(position=(0, 0, 0), look_at=(0, 0, 1))
    np.testing.assert_allclose(cam.quaternion, (0, 0, 1, 0), atol=1e-6)
    obj = kb.Cube(euler=(np.pi, 0, 0))
    np.testing.assert_allclose(obj.quaternion, (0, 1, 0, 0), atol=1e-6)
    with pytest.raises(TypeError, match="at most one of look_at, euler and quaternion"):
        kb.Cube(euler=(0, 0, 0), look_at=(1, 0, 0))


def test_look_at_points_minus_z_at_target_with_up_towards_world_z():
    cam = kb.PerspectiveCamera(position=(7.48, -6.51, 5.34), look_at=(0, 0, 0))
    rot = cam.rotation_matrix
    direction = -rot[:, 2]
    expected = -np.array([7.48, -6.51, 5.34]) / np.linalg.norm([7.48, -6.51, 5.34])
    np.testing.assert_allclose(direction, expected, atol=1e-6)
    assert abs(rot[2, 0]) < 1e-6  # camera x axis is horizontal
    assert rot[2, 1] > 0  # camera up points upwards


def test_cube_bounds_bbox_and_aabbox():
    cube = kb.Cube(position=(1, 2, 3), scale=(1, 2, 0.5))
    np.testing.assert_allclose(cube.aabbox, [[0, 0, 2.5], [2, 4, 3.5]], atol=1e-6)
    assert cube.bbox_3d.shape == (8, 3)
    np.testing.assert_allclose(cube.bbox_3d[0], [0, 0, 2.5])  # (xmin, ymin, zmin) first
    np.testing.assert_allclose(cube.bbox_3d[1], [0, 0, 3.5])  # then z varies fastest
    rotated = kb.Cube(scale=(2, 1, 1), euler=(0, 0, np.pi / 2))
    np.testing.assert_allclose(rotated.aabbox, [[-1, -2, -1], [1, 2, 1]], atol=1e-5)
    assert kb.Sphere().bounds.tolist() == [[-1, -1, -1], [1, 1, 1]]


def test_matrix_world_maps_local_to_world():
    obj = kb.Cube(position=(1, 2, 3), euler=(0, 0, np.pi / 2))
    p = obj.matrix_world @ np.array([1.0, 0, 0, 1])
    np.testing.assert_allclose(p[:3], [1, 3, 3], atol=1e-6)


def test_keyframe_notification_reaches_each_view_once_with_frame():
    scene = kb.Scene()
    view = RecordingView(scene)
    cube = kb.Cube()
    scene += cube
    scene += cube  # adding twice is a no-op
    view.calls.clear()
    cube.position = (1, 0, 0)
    cube.keyframe_insert("position", 7)
    assert view.calls == [("change", cube, "position"), ("keyframe", cube, "position", 7)]
    with pytest.raises(KeyError, match="no property 'positon'"):
        cube.keyframe_insert("positon", 1)


def test_link_view_replays_scene_and_assets_and_unlink_removes():
    scene = kb.Scene()
    cube = kb.Cube(material=kb.FlatMaterial())
    scene += cube
    view = RecordingView(scene)
    assert view.calls[0] == ("add", scene)
    assert ("add", cube) in view.calls and ("add", cube.material) in view.calls
    scene.unlink_view(view)
    assert ("remove", cube) in view.calls
    view.calls.clear()
    cube.position = (0, 0, 1)
    assert view.calls == []
    with pytest.raises(ValueError, match="not linked"):
        scene.unlink_view(view)


def test_adding_object_adds_material_and_assigning_material_adds_it():
    scene = kb.Scene()
    mat = kb.PrincipledBSDFMaterial(color="red")
    cube = kb.Cube(material=mat)
    scene += cube
    assert mat in scene.assets
    mat2 = kb.FlatMaterial()
    cube.material = mat2
    assert mat2 in scene.assets


def test_adding_a_camera_makes_it_active():
    scene = kb.Scene()
    cam1, cam2 = kb.PerspectiveCamera(), kb.OrthographicCamera()
    scene += cam1
    assert scene.camera is cam1
    scene += cam2
    assert scene.camera is cam2
    scene.camera = cam1
    assert scene.camera is cam1
    cam3 = kb.PerspectiveCamera()
    scene.camera = cam3
    assert cam3 in scene.assets


def test_scene_defaults_and_validation():
    scene = kb.Scene()
    assert (scene.frame_start, scene.frame_end, scene.frame_rate, scene.step_rate) == (1, 48, 24, 240)
    assert scene.resolution == (512, 512) and scene.gravity.tolist() == [0, 0, -10]
    with pytest.raises(ValueError, match=r"step_rate \(250\) must be a multiple of frame_rate \(24\)"):
        scene.step_rate = 250
    scene.set_rates(25, 250)
    assert (scene.frame_rate, scene.step_rate) == (25, 250)
    with pytest.raises(ValueError, match=r"Scene.resolution must be N or WxH .*got \(-3, 10\)"):
        kb.Scene(resolution=(-3, 10))
    with pytest.raises(ValueError, match="frame_end"):
        kb.Scene(frame_start=10, frame_end=5)


def test_get_value_at_interpolates_linearly_and_holds_outside():
    cube = kb.Cube()
    cube.position = (0, 0, 0)
    cube.keyframe_insert("position", 0)
    cube.position = (10, -4, 2)
    cube.keyframe_insert("position", 10)
    np.testing.assert_allclose(cube.get_value_at("position", 2.5), (2.5, -1, 0.5), atol=1e-6)
    np.testing.assert_allclose(cube.get_value_at("position", -5), (0, 0, 0))
    np.testing.assert_allclose(cube.get_value_at("position", 50), (10, -4, 2))
    values = cube.get_values_over_time("position", frames=[0, 5, 10])
    assert values.shape == (3, 3) and values.dtype == np.float32
    with cube.at_frame(5):
        np.testing.assert_allclose(cube.position, (5, -2, 1))
    np.testing.assert_allclose(cube.position, (10, -4, 2))


def test_quaternion_keyframes_interpolate_by_slerp():
    cube = kb.Cube()
    cube.quaternion = kb.Quaternion(axis="Z", angle=0.0)
    cube.keyframe_insert("quaternion", 0)
    cube.quaternion = kb.Quaternion(axis="Z", angle=np.pi / 2)
    cube.keyframe_insert("quaternion", 4)
    q = cube.get_value_at("quaternion", 1)
    expected = kb.Quaternion(axis="Z", angle=np.pi / 8)
    np.testing.assert_allclose(q, np.asarray(expected), atol=1e-6)
    assert abs(np.linalg.norm(q) - 1) < 1e-6


def test_at_frame_does_not_notify_views():
    scene = kb.Scene()
    cube = kb.Cube()
    scene += cube
    cube.keyframe_insert("position", 1)
    view = RecordingView(scene)
    view.calls.clear()
    with cube.at_frame(3):
        pass
    assert view.calls == []


def test_table_view_dispatches_by_class_and_property():
    log = []

    class Backend(TableView):
        builders = {kb.Scene: None, kb.Material: None,
                    kb.PhysicalObject: lambda view, asset: {"uid": asset.uid}}
        setters = {kb.PhysicalObject: {"position": lambda v, a, o, val: log.append(("pos", a.uid))},
                   kb.Sphere: {"mass": lambda v, a, o, val: log.append(("mass", val))}}
        keyframers = {kb.Object3D: {"position": lambda v, a, o, f: log.append(("key", f))}}

    scene = kb.Scene()
    view = Backend(scene)
    sphere = kb.Sphere(mass=3.0)
    sphere.keyframe_insert("position", 2)
    scene += sphere
    assert view.backend_object(sphere) == {"uid": "Sphere"}
    assert log == [("pos", "Sphere"), ("mass", 3.0), ("key", 2)]
    with pytest.raises(TypeError, match="Backend cannot represent a PointLight"):
        scene += kb.PointLight()


def test_colors():
    assert kb.get_color("#f00") == (1, 0, 0, 1)
    assert kb.get_color("00ff0080").a == pytest.approx(128 / 255)
    assert kb.get_color("red") == (1, 0, 0, 1)
    assert kb.Color.from_hsv(0.5, 1, 1).rgb == pytest.approx((0, 1, 1))
    with pytest.raises(ValueError, match=r"Color.r must be in \[0, 1\], got 1.5"):
        kb.Color(1.5, 0, 0)
    with pytest.raises(ValueError, match="unknown colour name 'reddish'"):
        kb.get_color("reddish")
    with pytest.raises(ValueError, match="hex colour must have 3, 4, 6 or 8 hex digits"):
        kb.get_color("#12345")


def test_quaternion_type():
    q = kb.Quaternion(axis=(0, 0, 1), angle=np.pi / 2)
    np.testing.assert_allclose(q.rotate([1, 0, 0]), [0, 1, 0], atol=1e-12)
    r = kb.Quaternion(matrix=q.rotation_matrix)
    np.testing.assert_allclose(np.asarray(r), np.asarray(q), atol=1e-12)
    np.testing.assert_allclose(np.asarray(q * q.inverse), [1, 0, 0, 0], atol=1e-12)
    assert list(kb.Quaternion()) == [1.0, 0.0, 0.0, 0.0]
    with pytest.raises(ValueError, match="not a proper rotation"):
        kb.Quaternion(matrix=np.diag([1, 1, -1]))


def test_lights_and_materials_validate():
    assert kb.DirectionalLight(shadow_softness=0.1).shadow_softness == pytest.approx(0.1)
    area = kb.RectAreaLight(width=2, height=0.5)
    assert (area.width, area.height) == (2.0, 0.5)
    with pytest.raises(ValueError, match="PointLight.intensity must be in"):
        kb.PointLight(intensity=-1)
    with pytest.raises(ValueError, match="PrincipledBSDFMaterial.metallic"):
        kb.PrincipledBSDFMaterial(metallic=2)
    tex = kb.Texture(filename="sky.exr", mapping="environment")
    assert kb.FlatMaterial(color=tex).color is tex
    assert kb.Scene(background=tex).background is tex


def test_texture_projection_height_validates():
    tex = kb.Texture(filename="sky.exr", mapping="environment")
    assert tex.projection_height == 0.0  # default: plain lookup by direction
    tex.projection_height = 1.75
    assert tex.projection_height == pytest.approx(1.75)
    for bad in (-0.5, float("inf"), float("nan")):
        with pytest.raises(ValueError, match=r"Texture.projection_height must be in \[0, inf\]"):
            kb.Texture(projection_height=bad)
    with pytest.raises(TypeError, match="Texture.projection_height must be a number"):
        tex.projection_height = "high"
    assert tex.projection_height == pytest.approx(1.75)  # a rejected value changes nothing


def test_keyframe_delete_notifies_and_names_missing_frames():
    scene = kb.Scene()
    view = RecordingView(scene)
    cube = kb.Cube()
    scene += cube
    cube.keyframe_insert("position", 3)
    view.calls.clear()
    cube.keyframe_delete("position", 3)
    assert view.calls == [("keyframe_delete", cube, "position", 3)]
    assert cube.keyframes["position"] == {}
    with pytest.raises(KeyError, match=r"no keyframe of 'position' at frame 3; keyed frames: \[\]"):
        cube.keyframe_delete("position", 3)


@pytest.mark.parametrize("resolution, expected", [(64, (64, 64)), ("320x240", (320, 240)),
                                                  ("48", (48, 48)), ((30, 20), (30, 20)),
                                                  ("320,240", (320, 240))])
def test_scene_from_flags_like_upstream_scripts(resolution, expected):
    from types import SimpleNamespace
    flags = SimpleNamespace(frame_start=1, frame_end=12, frame_rate=12, step_rate=240,
                            resolution=resolution)
    scene = kb.Scene.from_flags(flags)
    assert scene.resolution == expected and scene.frame_end == 12 and scene.frame_rate == 12
    with pytest.raises(ValueError, match="resolution must be N or WxH .*, got 'big'"):
        kb.Scene.from_flags(SimpleNamespace(**{**vars(flags), "resolution": "big"}))


def test_upstream_color_and_quaternion_spellings():
    assert kb.get_color(0xFF8000) == kb.Color(1, 128 / 255, 0)
    assert kb.Color.from_hexint(0x0000FF, alpha=0.5).a == 0.5
    assert kb.Color.from_hsv(0, 1, 1, alpha=0.25) == (1, 0, 0, 0.25)
    assert kb.Color(1, 0, 0).hexstr_short == "#f00f"
    assert kb.PointLight(color=0xFFEDD0).color.hexstr == "#ffedd0ff"
    with pytest.raises(ValueError, match=r"hex integer colour must be in \[0, 0xFFFFFF\]"):
        kb.get_color(0x1000000)
    q = kb.Quaternion(axis=[1, 0, 0], degrees=90)
    np.testing.assert_allclose(np.asarray(q), kb.Quaternion(axis="X", radians=np.pi / 2))
    assert q.degrees == pytest.approx(90) and q.angle == pytest.approx(np.pi / 2)
    np.testing.assert_allclose(q.axis, [1, 0, 0])
    with pytest.raises(TypeError, match="give the rotation angle once"):
        kb.Quaternion(axis="X", angle=1, degrees=2)


def test_changes_inside_a_texture_reach_the_views_of_its_users():
    scene = kb.Scene()
    view = RecordingView(scene)
    tex = kb.Texture(filename="a.png")
    mat = kb.PrincipledBSDFMaterial(color=tex)
    cube = kb.Cube(material=mat)
    scene += cube
    scene.background = tex
    assert {(o.uid if hasattr(o, "uid") else "scene", n) for o, n in tex.owners} == {
        (mat.uid, ("color",)), ("scene", ("background",))}
    view.calls.clear()
    tex.filename = "b.png"
    assert ("change", mat, "color") in view.calls  # the material re-reads its colour
    assert ("change", scene, "background") in view.calls
    assert ("change", tex, "filename") in view.calls  # Texture is in no scene, views still hear
    assert view.calls.count(("change", mat, "color")) == 1
    # once replaced, the texture no longer drives the material
    mat.color = "red"
    scene.background = "black"
    assert tex.owners == []
    view.calls.clear()
    tex.filename = "c.png"
    assert view.calls == []


def test_owner_notifications_cascade_once_and_stop_when_replaced():
    scene = kb.Scene()
    view = RecordingView(scene)
    mat = kb.FlatMaterial(color="red")
    cube = kb.Cube(material=mat)
    scene += cube
    view.calls.clear()
    mat.color = "blue"
    assert view.calls == [("change", mat, "color"), ("change", cube, "material")]
    # a material that is nobody's value any more is not forwarded
    cube.material = kb.FlatMaterial()
    view.calls.clear()
    mat.color = "green"
    assert ("change", cube, "material") not in view.calls

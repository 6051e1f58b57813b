"""The output contract declared once (kubric.io.schema): MOVi names/dtypes, the writer checks
scenes against it, schema-declared layers flow through the writer and reader, Markdown docs."""

import numpy as np
import pytest

from kubric.io import layers as layers_io
from kubric.io.layers import LayerFormat
from kubric.io.scene_writer import write_scene
from kubric.io.schema import Feature, Schema, SchemaError, schema_markdown
from kubric.pipeline.recipe import schema_of as get_schema

# Upstream's published MOVi features (name, dtype, shape with the sequence dim first), typed
# from the MOVi dataset builders' feature declarations.
UPSTREAM_MOVI = {
    "metadata/video_name": ("str", ()), "metadata/width": ("int32", ()),
    "metadata/height": ("int32", ()), "metadata/num_frames": ("int32", ()),
    "metadata/num_instances": ("uint16", ()), "metadata/depth_range": ("float32", (2,)),
    "metadata/forward_flow_range": ("float32", (2,)),
    "metadata/backward_flow_range": ("float32", (2,)),
    "instances/mass": ("float32", ("N",)), "instances/friction": ("float32", ("N",)),
    "instances/restitution": ("float32", ("N",)),
    "instances/positions": ("float32", ("N", "T", 3)),
    "instances/quaternions": ("float32", ("N", "T", 4)),
    "instances/velocities": ("float32", ("N", "T", 3)),
    "instances/angular_velocities": ("float32", ("N", "T", 3)),
    "instances/bboxes_3d": ("float32", ("N", "T", 8, 3)),
    "instances/image_positions": ("float32", ("N", "T", 2)),
    "instances/bboxes": ("float32", ("N", "V", 4)), "instances/bbox_frames": ("int32", ("N", "V")),
    "instances/visibility": ("uint16", ("N", "T")),
    "camera/focal_length": ("float32", ()), "camera/sensor_width": ("float32", ()),
    "camera/field_of_view": ("float32", ()), "camera/positions": ("float32", ("T", 3)),
    "camera/quaternions": ("float32", ("T", 4)),
    "events/collisions/instances": ("uint16", ("K", 2)),
    "events/collisions/frame": ("int32", ("K",)), "events/collisions/force": ("float32", ("K",)),
    "events/collisions/position": ("float32", ("K", 3)),
    "events/collisions/image_position": ("float32", ("K", 2)),
    "events/collisions/contact_normal": ("float32", ("K", 3)),
    "video": ("uint8", ("T", "H", "W", 3)), "segmentations": ("uint8", ("T", "H", "W", 1)),
    "forward_flow": ("uint16", ("T", "H", "W", 2)), "backward_flow": ("uint16", ("T", "H", "W", 2)),
    "depth": ("uint16", ("T", "H", "W", 1)), "normal": ("uint16", ("T", "H", "W", 3)),
    "object_coordinates": ("uint16", ("T", "H", "W", 3)),
}
UPSTREAM_A_LABELS = {"shape_label": ("cube", "cylinder", "sphere"), "size_label": ("small", "large"),
                     "color_label": ("blue", "brown", "cyan", "gray", "green", "purple", "red",
                                     "yellow"), "material_label": ("metal", "rubber")}


@pytest.mark.parametrize("name", ["movi_a", "movi_b", "movi_c", "movi_d", "movi_e", "movi_f"])
def test_movi_schemas_keep_upstream_names_and_dtypes(name):
    schema = get_schema(name)
    for feature, (dtype, shape) in UPSTREAM_MOVI.items():
        f = schema[feature]
        assert (f.dtype, f.full_shape()) == (dtype, shape), feature
    extras = {"movi_a": {"instances/shape_label", "instances/size_label", "instances/color",
                         "instances/color_label", "instances/material_label"},
              "movi_b": {"instances/shape_label", "instances/color", "instances/material_label",
                         "background_color"}}.get(name, {"background", "instances/scale",
                                                          "instances/is_dynamic"})
    assert extras <= set(schema.names)


def test_movi_a_class_labels_are_upstreams():
    schema = get_schema("movi_a")
    for key, names in UPSTREAM_A_LABELS.items():
        assert schema[f"instances/{key}"].names == names
    assert len(get_schema("movi_b")["instances/shape_label"].names) == 11


def test_movi_recipes_declare_their_schema():
    from kubric.pipeline import get_recipe
    for name in ("movi_a", "movi_b", "movi_c", "movi_d", "movi_e", "movi_f"):
        assert get_recipe(name).schema is get_schema(name)


def test_unknown_schema_is_one_line():
    with pytest.raises(SchemaError, match=r"unknown recipe schema 'movi_z' \(schemas: .*movi_a"):
        get_schema("movi_z")


def test_bad_declarations_are_refused():
    with pytest.raises(SchemaError, match="dtype 'float16'"):
        Feature("x", "float16", (), "meta:x")
    with pytest.raises(SchemaError, match="shape entry 'Q'"):
        Feature("x", "float32", ("Q",), "meta:x")
    with pytest.raises(SchemaError, match="source 'file:x'"):
        Feature("x", "float32", (), "file:x")
    with pytest.raises(SchemaError, match="neither standard nor declared"):
        Schema("bad", (Feature("albedo", "uint16", ("T", "H", "W", 3), "layer:albedo", "png"),))
    with pytest.raises(SchemaError, match="declared twice"):
        Schema("bad", (Feature("a", "int32", (), "meta:a"), Feature("a", "int32", (), "meta:b")))


def test_markdown_lists_every_feature_with_its_contract():
    schema = get_schema("movi_a")
    text = schema_markdown(schema)
    for f in schema.features:
        assert f"| `{f.name}` |" in text
    assert "| `instances/positions` | float32 | (N, T, 3) | none | m |" in text
    assert "class label (cube, cylinder, sphere)" in text


def _toy_schema():
    return Schema("toy_albedo", (
        Feature("metadata/video_name", "str", (), "scene_name", "text"),
        Feature("albedo", "uint16", ("T", "H", "W", 3), "layer:albedo", "png"),
        Feature("metadata/answer", "int32", (), "meta:answer"),
    ), layers={"albedo": LayerFormat("albedo_{:05d}.png", 3, "unit")})


def test_schema_layer_flows_through_writer_and_reader(tmp_path):
    schema = _toy_schema()
    rng = np.random.RandomState(0)
    albedo = rng.rand(2, 4, 5, 3).astype(np.float32)
    write_scene(schema, tmp_path, {"albedo": albedo},
                {"metadata": {"answer": 42, "resolution": [5, 4], "num_frames": 2}})
    assert sorted(p.name for p in tmp_path.glob("albedo_*.png")) == ["albedo_00000.png",
                                                                     "albedo_00001.png"]
    back = layers_io.read_layer(tmp_path, "albedo", formats=schema.layers)
    assert np.max(np.abs(back - albedo)) <= 0.5 / 65535 + 1e-7
    raw = layers_io.read_layer(tmp_path, "albedo", formats=schema.layers, raw=True)
    assert raw.dtype == np.uint16 and np.array_equal(raw, np.rint(albedo * 65535))
    with pytest.raises(ValueError, match="unknown layer"):  # not a standard layer
        layers_io.write_image_dict({"albedo": albedo}, tmp_path / "x")


def test_writer_refuses_scene_off_contract_and_writes_nothing(tmp_path):
    schema = _toy_schema()
    albedo = np.zeros((1, 2, 2, 3), np.float32)
    with pytest.raises(SchemaError, match=r"feature 'metadata/answer'.*no field 'answer'"):
        write_scene(schema, tmp_path / "a", {"albedo": albedo}, {"metadata": DIMS})
    with pytest.raises(SchemaError, match="needs layer 'albedo'"):
        write_scene(schema, tmp_path / "b", {}, {"metadata": {"answer": 1, **DIMS}})
    with pytest.raises(SchemaError, match=r"layer 'albedo' has \(T, H, W\) \(1, 2, 2\), the "
                       r"metadata says \(1, 3, 2\)"):
        write_scene(schema, tmp_path / "c", {"albedo": albedo},
                    {"metadata": {"answer": 1, "resolution": [2, 3], "num_frames": 1}})
    with pytest.raises(SchemaError, match="must give 'resolution'"):
        write_scene(schema, tmp_path / "d", {"albedo": albedo}, {"metadata": {"answer": 1}})
    assert not any((tmp_path / d).exists() for d in "abcd")


DIMS = {"resolution": [2, 2], "num_frames": 1}


def test_writer_applies_every_conversion_the_packer_will(tmp_path):
    """A value that passes the presence check but not the packer's conversion or cast is refused
    when the scene is written (the MOVi-B background_color bug), naming the feature."""
    schema = Schema("toy_colour", (Feature("background_color", "float32", (3,),
                                           "meta:background", convert="hex_to_rgb"),
                                   Feature("metadata/count", "uint8", (), "meta:count")))
    ok = {"metadata": {"background": "#5998b2ff", "count": 3, **DIMS}}
    write_scene(schema, tmp_path / "ok", {}, ok)  # '#rrggbbaa' (kb.Color.hexstr) is a colour
    from kubric.io.scene_reader import SceneReader
    rgb = SceneReader(tmp_path / "ok", schema).example()["background_color"]
    assert np.allclose(rgb, np.array([0x59, 0x98, 0xb2]) / 255)
    for field, value, message in [("background", "blue", "hex_to_rgb: 'blue' is not a"),
                                  ("count", 300, r"values \[300, 300\] do not fit uint8"),
                                  ("count", 2.5, "non-integer values")]:
        bad = {"metadata": {**ok["metadata"], field: value}}
        with pytest.raises(SchemaError, match=f"schema 'toy_colour': the scene written does not "
                                              f"pack: .*{message}"):
            write_scene(schema, tmp_path / field, {}, bad)
    assert not (tmp_path / "a").exists() and not (tmp_path / "b").exists()


def test_docs_features_page_is_the_schemas():
    """docs/features.md holds every registered schema's table (generated; the docs test keeps it
    current), and every feature has a doc."""
    from kubric import docgen
    page = (docgen.docs_dir() / "features.md").read_text()
    assert schema_markdown("movi_a") in page and schema_markdown("movi_e") in page
    assert docgen.undocumented_features() == []


def test_the_write_time_check_holds_one_layer_at_a_time(tmp_path, monkeypatch):
    """check_written reads every feature as the packer does, but drops a layer's samples after
    its last feature (the scene is not held in memory a second time)."""
    from kubric.io import scene_reader
    schema = Schema("toy_two_layers", (
        Feature("albedo", "uint16", ("T", "H", "W", 3), "layer:albedo", "png"),
        Feature("albedo_range", "float32", (2,), "range:albedo"),
        Feature("shade", "uint16", ("T", "H", "W", 3), "layer:shade", "png"),
    ), layers={"albedo": LayerFormat("albedo_{:05d}.png", 3, "unit"),
               "shade": LayerFormat("shade_{:05d}.png", 3, "unit")})
    held = []
    feature = scene_reader.SceneReader.feature

    def spy(self, f):
        value = feature(self, f)
        held.append((f.name, sorted(self._layers)))
        return value

    monkeypatch.setattr(scene_reader.SceneReader, "feature", spy)
    arr = np.random.RandomState(1).rand(2, 3, 4, 3).astype(np.float32)
    write_scene(schema, tmp_path, {"albedo": arr, "shade": arr},
                {"metadata": {"resolution": [4, 3], "num_frames": 2}})
    assert held == [("albedo", ["albedo"]), ("albedo_range", ["albedo"]), ("shade", ["shade"])]

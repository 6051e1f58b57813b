"""The encodings registry (kubric.io.encodings): every layer kind and feature encoding is a class
registered under its stored name; adding one is one class, and the writer, reader, packer,
physical decode and pictures all use it; the layer vocabulary is declared once."""

import numpy as np
import pytest

from kubric.annotations import pictures
from kubric.io import encodings, png_io
from kubric.io.encodings import FixedInterval, LayerKind, register
from kubric.io.layers import (
    LAYER_KINDS,
    LAYERS,
    RENDERED_LAYERS,
    LayerFormat,
    read_image_dict,
    write_image_dict,
)
from kubric.io.scene_reader import SceneReader
from kubric.io.schema import ENCODINGS, Feature, Schema, SchemaError


def test_registries_hold_the_stored_names():
    assert tuple(LAYER_KINDS) == ("image8", "tiff", "labels", "scaled", "signed_unit", "unit",
                                 "bitmask", "vector", "edge_bits")
    assert tuple(ENCODINGS) == ("none", "png", "zlib", "text", "class_label", "bbox")
    for name, kind in LAYER_KINDS.items():
        assert isinstance(kind, LayerKind) and kind.name == name
    # a LayerFormat built from the string (stored JSON, recipes) or the class is the same
    assert LayerFormat("h_{:05d}.tiff", 1, encodings.Tiff) == LayerFormat("h_{:05d}.tiff", 1,
                                                                          "tiff")
    assert LAYERS["normal"].type is LAYER_KINDS["signed_unit"]
    with pytest.raises(ValueError, match=r"layer kind 'nope' is not one of \('image8'"):
        encodings.layer_kind("nope")
    with pytest.raises(SchemaError, match=r"encoding 'jpeg' is not one of \('none', 'png'"):
        Feature("x", "uint8", ("T", "H", "W", 3), "layer:rgba[:3]", "jpeg")
    with pytest.raises(SchemaError, match="png features are"):
        Feature("x", "float32", ("T", "H", "W", 3), "layer:rgba[:3]", "png")
    with pytest.raises(SchemaError, match="class labels need names"):
        Feature("x", "int64", (), "meta:x", "class_label")
    with pytest.raises(TypeError, match="not a named LayerKind"):
        register(int)


def test_renderer_and_viewer_vocabulary_derive_from_the_one_declaration():
    from kubric.renderer import base
    from kubric.viewer.source import VIEW_LAYERS
    assert base.ALL_LAYERS == RENDERED_LAYERS and set(RENDERED_LAYERS) < set(LAYERS)
    assert base.ALL_LAYERS == ("rgba", "depth", "z", "segmentation", "forward_flow",
                               "backward_flow", "normal", "object_coordinates", "uv")
    assert base.ANNOTATION_LAYERS == base.ALL_LAYERS[1:]
    assert VIEW_LAYERS == tuple(LAYERS)


@pytest.fixture
def percent_kind():
    """A new layer kind, one class: values in [0, 100] stored as 16-bit samples."""
    @register
    class Percent(FixedInterval):
        name = "test_percent"
        lo, hi = 0.0, 100.0
    yield Percent
    del LAYER_KINDS["test_percent"]


def test_a_new_layer_kind_is_one_class(percent_kind, tmp_path):
    rng = np.random.RandomState(0)
    values = rng.uniform(0, 100, (2, 5, 7, 1)).astype(np.float32)
    fmt = LayerFormat("share_{:05d}.png", 1, percent_kind)
    assert fmt.kind == "test_percent"
    scene = tmp_path / "scene"
    write_image_dict({"share": values}, scene, formats={"share": fmt})
    # the file: 16-bit samples round(v / 100 · 65535), read independently
    stored = png_io.read_png(scene / "share_00001.png")
    assert stored.dtype == np.uint16
    assert np.array_equal(stored[..., 0], np.rint(values[1, ..., 0] / 100.0 * 65535))
    # the reader decodes within half a step
    back = read_image_dict(scene, formats={"share": fmt})["share"]
    assert back.dtype == np.float32 and np.max(np.abs(back - values)) <= 50 / 65535 + 1e-5
    # the packer stores the samples; the physical decode gives the values back
    schema = Schema("test_percent", (Feature("share", "uint16", ("T", "H", "W", 1),
                                             "layer:share", "png", unit="%"),),
                    {"share": fmt})
    (scene / "metadata.json").write_text('{"metadata": {"resolution": [7, 5], "num_frames": 2}}')
    packed = SceneReader(scene, schema).example()
    assert packed["share"].dtype == np.uint16
    assert np.array_equal(packed["share"][1], stored[..., :1])
    physical = schema.physical(packed)["share"]
    assert physical.dtype == np.float32 and np.max(np.abs(physical - values)) <= 50 / 65535 + 1e-5
    # and it draws itself (values / 100 as grey)
    pic = pictures.picture("share", back[0], kind="test_percent")
    assert pic.shape == (5, 7, 3)
    assert np.array_equal(pic[..., 0], (np.clip(back[0, ..., 0] / 100, 0, 1) * 255 + 0.5)
                          .astype(np.uint8))
    with pytest.raises(ValueError, match=r"values must lie in \[0.0, 100.0\], got range \[-"):
        write_image_dict({"share": values - 50}, tmp_path / "bad", formats={"share": fmt})


def test_physical_decode_needs_the_range_of_quantised_layers():
    schema = Schema("test_ranges", (
        Feature("flow", "uint16", ("T", "H", "W", 2), "layer:forward_flow", "zlib"),))
    with pytest.raises(SchemaError, match=r"'flow': decoding layer 'forward_flow' needs its "
                                          r"range.*has none"):
        schema.physical({"flow": np.zeros((1, 2, 2, 2), np.uint16)})
    schema = Schema("test_ranges", schema.features + (
        Feature("flow_range", "float32", (2,), "range:forward_flow"),))
    q = np.array([0, 65535, 32768], np.uint16).reshape(1, 1, 3, 1).repeat(2, -1)
    flow = schema.physical({"flow": q, "flow_range": np.float32([-3, 5])})["flow"]
    assert np.allclose(flow[0, 0, :, 0], [-3, 5, -3 + 8 * 32768 / 65535], atol=1e-6)

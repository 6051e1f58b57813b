"""`kubric inspect` on a synthetic scene directory written with kubric.file_io."""

import subprocess
import sys

import numpy as np
import pytest
from PIL import Image

from kubric import file_io
from kubric.annotations import pictures
from kubric.core.camera_geometry import BACKGROUND_DEPTH
from kubric.pipeline.cli import cmd_inspect
from kubric.pipeline.inspect import (
    GUTTER,
    HEADER,
    MIN_TILE_WIDTH,
    colourise,
    inspect_scene,
    tile_scale,
)


def _scene_dir(tmp_path, t=3, h=8, w=10):
    rng = np.random.default_rng(0)
    depth = np.full((t, h, w, 1), BACKGROUND_DEPTH, np.float32)
    depth[:, 2:6, 3:7] = 5.0
    seg = np.zeros((t, h, w, 1), np.uint32)
    seg[:, 2:6, 3:7] = 1
    seg[:, 6:8, 0:5, 0] = np.arange(2, 7)  # labels 2..6
    normal = np.zeros((t, h, w, 3), np.float32)
    normal[..., 2] = 1.0
    layers = {"rgba": rng.integers(0, 255, (t, h, w, 4), dtype=np.uint8), "depth": depth,
              "segmentation": seg, "normal": normal,
              "forward_flow": rng.normal(size=(t, h, w, 2)).astype(np.float32)}
    d = tmp_path / "scene_00000003"
    file_io.write_image_dict(layers, d)
    file_io.write_json({"metadata": {"seed": 3, "resolution": [w, h], "num_frames": t},
                        "camera": {"positions": [[0, 0, 0], [3, 4, 0], [3, 4, 0]]},
                        "instances": [{"shape": "cube", "color_label": "red",
                                       "visibility": [16, 16, 16], "bbox_frames": [0, 1, 2]}]},
                       d / "metadata.json")
    file_io.write_json({"collisions": [{"frame": 1.5}]}, d / "events.json")
    return d


def test_inspect_summary_and_contact_sheet(tmp_path, capsys, monkeypatch):
    d = _scene_dir(tmp_path)
    monkeypatch.chdir(tmp_path)
    written = sorted(p.name for p in d.iterdir())
    text = inspect_scene(d)
    assert sorted(p.name for p in d.iterdir()) == written  # read-only on the scene
    assert "seed: 3" in text and "instances: 1" in text and "cube red" in text
    assert "camera path length: 5.000 m" in text and "collisions: 1" in text
    assert "depth" in text and "(3, 8, 10, 1)" in text
    assert f"contact sheet: {tmp_path / 'scene_00000003_contact_sheet.png'}" in text
    labelled = np.asarray(Image.open(tmp_path / "scene_00000003_contact_sheet.png"))
    k = tile_scale(10)  # tiles enlarged (nearest) so that the layer names fit above them
    assert k * 10 >= MIN_TILE_WIDTH and labelled.shape == (HEADER + 3 * 8 * k,
                                                           GUTTER + 5 * 10 * k, 3)
    sheet = labelled[HEADER:, GUTTER:][::k, ::k]
    assert sheet.shape == (3 * 8, 5 * 10, 3)
    check_labels(labelled, ["rgb", "segmentation", "depth", "forward_flow", "normal"], 10 * k,
                 [0, 1, 2], 8 * k)
    # depth column: the object in the depth map's colours, background black; segmentation
    # column: label coloured
    depth_col = sheet[:8, 20:30]
    assert depth_col[3, 4].max() > 0 and depth_col[0, 0].max() == 0
    seg_col = sheet[:8, 10:20]
    assert seg_col[3, 4].max() > 0 and seg_col[0, 0].max() == 0
    # one palette: every label has the colour its segmentation PNG stores for it
    labels, palette = file_io.read_palette_png(d / "segmentation_00000.png", return_palette=True)
    assert labels.max() == 6
    np.testing.assert_array_equal(seg_col, palette[labels[..., 0]])
    assert len({tuple(c) for c in palette[:7]}) == 7

    gif = tmp_path / "anim.gif"
    inspect_scene(d, gif)
    img = Image.open(gif)
    assert img.n_frames == 3 and img.size == (GUTTER + 50 * k, HEADER + 8 * k)
    # CLI: a missing directory is a one-line error
    class Args:
        scene_dir = str(tmp_path / "missing")
        sheet = None
    assert cmd_inspect(Args) == 2
    assert capsys.readouterr().err.count("\n") == 1


def check_labels(sheet, names, tile_w, frames, row_h):
    """Each column's header shows its layer name and each row's gutter its frame index: the
    strips equal the text drawn alone with PIL's default font at the same place."""
    from PIL import ImageDraw
    for k, name in enumerate(names):
        strip = Image.new("RGB", (tile_w, HEADER), "white")
        ImageDraw.Draw(strip).text((3, 2), name[:(tile_w - 4) // 6], fill="black")
        x = GUTTER + k * tile_w
        np.testing.assert_array_equal(sheet[:HEADER, x:x + tile_w], np.asarray(strip), name)
    for r, frame in enumerate(frames):
        cell = Image.new("RGB", (GUTTER, row_h), "white")
        ImageDraw.Draw(cell).text((3, 2), str(frame), fill="black")
        y = HEADER + r * row_h
        np.testing.assert_array_equal(sheet[y:y + row_h, :GUTTER], np.asarray(cell), frame)


def test_flow_colours_encode_direction():
    flow = np.zeros((1, 1, 2, 2), np.float32)
    flow[0, 0, 0] = (0.0, 1.0)   # rightwards (+x): red on the Middlebury wheel
    flow[0, 0, 1] = (1.0, 0.0)   # downwards (+y, a quarter turn): 13.5 of its 55 hues, orange
    rgb = colourise("forward_flow", flow)
    assert tuple(rgb[0, 0, 0]) == (255, 0, 0)
    assert tuple(rgb[0, 0, 1]) == (255, round(13.5 / 15 * 255), 0)
    np.testing.assert_array_equal(rgb[0], pictures.flow_picture(flow[0]))  # one colouriser


def test_label_palette_extends_the_png_palette_beyond_255_labels():
    from kubric.io.palette import label_palette
    big = label_palette(70000)  # 16-bit label PNGs have no palette; sheets still colour them
    np.testing.assert_array_equal(big[:256], file_io.default_palette())
    assert big.shape == (70000, 3) and big.dtype == np.uint8 and big[1:].max(axis=1).min() > 0
    with pytest.raises(ValueError, match="positive number of labels, got 0"):
        label_palette(0)


def _kubric(*args, cwd):
    return subprocess.run([sys.executable, "-m", "kubric", *args], cwd=cwd, capture_output=True,
                          text=True, timeout=120)


def test_inspect_cli_leaves_the_scene_untouched(tmp_path):
    d = _scene_dir(tmp_path / "data")
    work = tmp_path / "work"
    work.mkdir()
    before = {p.name: p.read_bytes() for p in d.iterdir()}
    r = _kubric("inspect", str(d), cwd=work)
    assert r.returncode == 0, r.stderr
    assert {p.name: p.read_bytes() for p in d.iterdir()} == before
    assert (work / "scene_00000003_contact_sheet.png").is_file()  # the current directory
    r = _kubric("inspect", str(d), "--sheet", str(d / "sheet.png"), cwd=work)  # when asked
    assert r.returncode == 0 and (d / "sheet.png").is_file()


@pytest.mark.parametrize("damage,needle", [
    ("truncated_png", "rgba_00001.png"), ("truncated_tiff", "depth_00001.tiff"),
    ("empty_png", "normal_00002.png"), ("missing_frame", "segmentation_"),
])
def test_inspect_names_a_damaged_frame_in_one_line(tmp_path, damage, needle):
    d = _scene_dir(tmp_path)
    if damage == "truncated_png":
        (d / "rgba_00001.png").write_bytes((d / "rgba_00001.png").read_bytes()[:60])
    elif damage == "truncated_tiff":
        (d / "depth_00001.tiff").write_bytes((d / "depth_00001.tiff").read_bytes()[:100])
    elif damage == "empty_png":
        (d / "normal_00002.png").write_bytes(b"")
    else:
        (d / "segmentation_00001.png").unlink()
    r = _kubric("inspect", str(d), cwd=tmp_path)
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 1 and "Traceback" not in r.stderr, r.stderr
    assert len(lines) == 1 and lines[0].startswith("kubric inspect: error: ") and needle in lines[0]
    assert not list(tmp_path.glob("*contact_sheet*"))  # no sheet from a damaged scene

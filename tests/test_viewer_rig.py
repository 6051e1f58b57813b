"""The viewer on a camera-rig scene in headless chromium: a tiny stereo MOVi-A scene rendered by
the raycast backend (bpy blocked), its cameras side by side under the stage, each showing its
own files (RGB, then the segmentation layer at another frame), and the rig's further camera in
the 3D view. Browser and helpers as tests/test_viewer_browser.py."""

import json

import numpy as np
import pytest
from test_rig import _worker
from test_viewer_browser import browser, image_pixels, open_scene, wait_for  # noqa: F401
from viewer_helpers import serving

from kubric import file_io
from kubric.io.palette import label_palette
from kubric.io.stored_schema import stored_schema


@pytest.fixture(scope="module")
def rig_scene(tmp_path_factory):
    root = tmp_path_factory.mktemp("viewer_rig")
    return root, _worker(root, 5, "frame_end=3", "cameras=stereo", "baseline=0.4",
                         "max_num_objects=4")


@pytest.fixture(scope="module")
def url(rig_scene):
    with serving(rig_scene[0]) as (address, _):
        yield f"http://{address[0]}:{address[1]}/"


def _tile(browser, camera, layer, frame):  # noqa: F811
    """The pixels of ``camera``'s tile once it shows ``layer`` at ``frame``."""
    wait_for(lambda: browser.execute_script(
        "const i = document.getElementById(arguments[0]); return i && i.complete && "
        "i.naturalWidth && i.getAttribute('src').endsWith(arguments[1])", f"rig-img-{camera}",
        f"/{layer}/{frame}.png"), f"{camera}'s {layer} frame {frame}")
    return image_pixels(browser, f"rig-img-{camera}")[..., :3].astype(int)


def test_rig_cameras_side_by_side(browser, rig_scene, url):  # noqa: F811
    _, scene = rig_scene
    formats = stored_schema(scene).layers
    open_scene(browser, url, scene.name)
    figures = browser.find_elements("css selector", "#rig-panel figure")
    assert [f.get_attribute("data-camera") for f in figures] == ["left", "right"]
    for camera, layer in (("left", "rgba"), ("right", "right_rgba")):
        rgb = file_io.read_layer(scene, layer, formats=formats)[0, ..., :3]
        assert np.array_equal(_tile(browser, camera, layer, 0), rgb)
    # the segmentation layer at frame 2: each camera its own labels, in the label palette
    browser.execute_script("const s = document.getElementById('layer-select');"
                           "s.value = 'segmentation'; s.dispatchEvent(new Event('change'));")
    for _ in range(2):
        browser.find_element("tag name", "body").send_keys("\ue014")  # → : the next frame
    segs = {}
    for camera, layer in (("left", "segmentation"), ("right", "right_segmentation")):
        segs[camera] = file_io.read_layer(scene, layer, formats=formats)[2, ..., 0]
        expected = label_palette(int(segs[camera].max()) + 1)[segs[camera]]
        assert np.abs(_tile(browser, camera, layer, 2) - expected).max() <= 2
    assert not np.array_equal(segs["left"], segs["right"])
    assert "right · right_segmentation · frame 2" in figures[1].text


def test_rig_in_the_3d_view(browser, rig_scene, url):  # noqa: F811
    _, scene = rig_scene
    open_scene(browser, url, scene.name)
    drawn = json.loads(wait_for(lambda: browser.find_element("id", "view3d").get_attribute(
        "data-rig"), "the 3D view's rig"))
    assert list(drawn) == ["right"]
    x, y = (round(v) for v in drawn["right"])
    pixel = browser.execute_script(
        "return Array.from(document.getElementById('view3d').getContext('2d')"
        ".getImageData(arguments[0], arguments[1], 1, 1).data);", x, y)
    assert pixel[:3] == [0x9a, 0xa4, 0xb2]  # the rig's colour: the right camera's dot

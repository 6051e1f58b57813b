"""The viewer page in headless chromium on synthetic scenes (no render): the loading state while
a frame's picture is on its way, label layers drawn without smoothing, deep links that reopen a
view, the filled segmentation overlay blended over RGB, and accumulated event frames (#40, #37).
Browser and helpers as tests/test_viewer_browser.py."""

import importlib.util
import io
import threading

import numpy as np
import pytest
from PIL import Image
from test_viewer_browser import browser, image_pixels, open_scene, wait_for  # noqa: F401
from viewer_helpers import H, T, W, serving, synthetic_scene

from kubric.io.event_h5 import encode_events
from kubric.io.palette import label_palette
from kubric.viewer.service import ViewerService

SCENE = "scene_00000003"


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    """One synthetic scene (a square, label 1, moving right one pixel a frame) with events."""
    root = tmp_path_factory.mktemp("viewer_views")
    synthetic_scene(root / SCENE)
    if importlib.util.find_spec("h5py"):  # the events test skips without it
        # one ON event per frame interval at (row 1, col 2 + i), one OFF at (row 2, col 2 + i)
        t = np.repeat(np.arange(1, T) * 1e6 / 12 - 10, 2)
        x = np.repeat(np.arange(1, T) + 2, 2).astype(np.uint16)
        y = np.tile([1, 2], T - 1).astype(np.uint16)
        p = np.tile([1, 0], T - 1).astype(np.uint8)
        (root / SCENE / "events.h5").write_bytes(
            encode_events({"x": x, "y": y, "t": t, "p": p}, np.full((2, H, W), 0.2)))
    return root


@pytest.fixture(scope="module")
def url(folder):
    with serving(folder) as (address, _):
        yield f"http://{address[0]}:{address[1]}/"


def stage_pixels(browser):  # noqa: F811
    """The stage's screen pixels inside its 1 px border, (H·k, W·k, 3) int."""
    png = browser.find_element("id", "stage").screenshot_as_png
    return np.asarray(Image.open(io.BytesIO(png)).convert("RGB")).astype(int)[1:-1, 1:-1]


def state(browser):  # noqa: F811
    return browser.execute_script("""
        const on = (id) => document.getElementById(id).checked;
        return {hash: location.hash, layer: document.getElementById('layer-select').value,
                frame: document.getElementById('frame-label').textContent,
                src: document.getElementById('main-img').getAttribute('src'),
                fill: on('overlay-fill'), outline: on('overlay-outline'), boxes: on('overlay-boxes'),
                opacity: document.getElementById('overlay-opacity').value,
                link: document.getElementById('deep-link').getAttribute('href'),
                error: document.getElementById('link-error').textContent};""")


class _SlowFrames(ViewerService):
    """Holds every RGB picture until ``release`` is set (a slow link)."""

    release = threading.Event()

    def picture_png(self, name, layer, index, lo=None, hi=None):
        if layer == "rgba":
            assert self.release.wait(30)
        return super().picture_png(name, layer, index, lo, hi)


def test_the_stage_says_loading_until_the_frame_arrives(browser, folder):  # noqa: F811
    _SlowFrames.release.clear()
    with serving(folder, service_class=_SlowFrames) as (address, _):
        try:
            browser.get(f"http://{address[0]}:{address[1]}/#/scene/{SCENE}")
            browser.refresh()
            loading = wait_for(lambda: (lambda e: e if e and e[0].is_displayed() else None)(
                browser.find_elements("id", "stage-loading")), "the loading state")[0]
            assert loading.text == "loading RGB, frame 0…"
            assert not browser.execute_script("return document.getElementById('main-img').complete")
        finally:
            _SlowFrames.release.set()
        wait_for(lambda: not loading.is_displayed(), "the loading state to go")
        assert browser.execute_script("return document.getElementById('main-img').naturalWidth") == W


def test_label_layers_are_drawn_pixel_for_pixel(browser, url, folder):  # noqa: F811
    """Segmentation scaled k× on screen: every screen pixel is its file pixel's palette colour
    (nearest neighbour: no colour between two labels appears)."""
    open_scene(browser, url, SCENE, "?layer=segmentation&frame=1&overlays=")
    seg = np.asarray(Image.open(folder / SCENE / "segmentation_00001.png"))
    shot = stage_pixels(browser)
    k = shot.shape[1] // W
    assert k >= 2 and shot.shape[:2] == (H * k, W * k)
    expected = np.kron(label_palette(2)[seg], np.ones((k, k, 1), int))
    assert np.abs(shot - expected).max() <= 2


def test_a_deep_link_reopens_the_view(browser, url):  # noqa: F811
    open_scene(browser, url, SCENE, "?frame=2&layer=depth&overlays=fill,boxes&opacity=40")
    got = state(browser)
    assert got["layer"] == "depth" and got["frame"].startswith("frame 2 / 2")
    assert "/depth/2.png?lo=" in got["src"]
    assert (got["fill"], got["boxes"], got["outline"], got["opacity"]) == (True, True, False, "40")
    assert got["error"] == ""
    assert got["hash"] == got["link"] == \
        f"#/scene/{SCENE}?frame=2&layer=depth&overlays=fill,boxes&opacity=40"
    # without overlays in the link, the outlines; with an empty list, none
    open_scene(browser, url, SCENE, "?frame=1")
    assert state(browser)["hash"] == \
        f"#/scene/{SCENE}?frame=1&layer=rgba&overlays=outline&opacity=90"
    open_scene(browser, url, SCENE, "?frame=1&overlays=")
    assert state(browser)["hash"] == f"#/scene/{SCENE}?frame=1&layer=rgba&overlays=&opacity=90"
    open_scene(browser, url, SCENE, "?frame=2&layer=depth&overlays=fill,boxes&opacity=40")
    # change the view: the address follows, and opening it again gives the same view
    browser.execute_script("const s = document.getElementById('frame-slider'); s.value = 1;"
                           "s.dispatchEvent(new Event('input'));"
                           "document.getElementById('overlay-outline').click();")
    moved = state(browser)
    assert moved["hash"] == \
        f"#/scene/{SCENE}?frame=1&layer=depth&overlays=outline,fill,boxes&opacity=40"
    open_scene(browser, url, SCENE, moved["hash"][len(f"#/scene/{SCENE}"):])
    again = state(browser)
    assert {k: again[k] for k in ("layer", "frame", "fill", "outline", "boxes", "opacity", "hash")} \
        == {k: moved[k] for k in ("layer", "frame", "fill", "outline", "boxes", "opacity", "hash")}


def test_a_deep_link_to_what_the_scene_lacks_is_named(browser, url):  # noqa: F811
    open_scene(browser, url, SCENE, "?frame=7&layer=uv&overlays=tracks&zoom=2")
    got = state(browser)
    for part in ('frame "7" (0..2)', 'layer "uv" (this scene: rgba, depth,',
                 'overlay "tracks" (available: outline, fill, boxes)', 'parameter "zoom"'):
        assert part in got["error"], got["error"]
    assert got["layer"] == "rgba" and got["frame"].startswith("frame 0 / 2")


def test_filled_segmentation_blends_over_rgb(browser, url, folder):  # noqa: F811
    """At opacity p the filled overlay shows (1 − p)·RGB + p·colour on the object and leaves
    the background as it was."""
    open_scene(browser, url, SCENE, "?frame=1&opacity=50&overlays=")
    wait_for(lambda: browser.execute_script(
        "const i = document.getElementById('fill-img'); return i.complete && i.naturalWidth"),
        "the fill picture")
    off = stage_pixels(browser)
    browser.find_element("id", "overlay-fill").click()
    wait_for(lambda: browser.execute_script(
        "return getComputedStyle(document.getElementById('fill-img')).opacity") == "0.5", "fill")
    on = stage_pixels(browser)
    seg = np.asarray(Image.open(folder / SCENE / "segmentation_00001.png"))
    k = on.shape[1] // W
    obj = np.kron(seg > 0, np.ones((k, k), bool))
    colour = label_palette(2)[1]
    assert np.abs(on[~obj] - off[~obj]).max() <= 2
    assert np.abs(on[obj] - (0.5 * off[obj] + 0.5 * colour)).max() <= 3


def test_event_frames_are_a_layer(browser, url):  # noqa: F811
    pytest.importorskip("h5py")
    open_scene(browser, url, SCENE, "?layer=events&frame=2")
    pixels = image_pixels(browser, "main-img")[..., :3]
    expected = np.zeros((H, W, 3), np.uint8)
    expected[1, 4] = (230, 57, 70)   # the ON event of interval (t_1, t_2] at col 2 + 2
    expected[2, 4] = (69, 123, 237)  # the OFF one
    np.testing.assert_array_equal(pixels, expected)
    assert browser.find_element("css selector", "#layer-select option[value=events]").text == \
        "events (ON red, OFF blue)"


def test_no_javascript_errors(browser):  # noqa: F811
    """Runs last (file order): the console collected no error over this file's tests."""
    errors = [e for e in browser.get_log("browser") if e["level"] == "SEVERE"]
    assert not errors, errors

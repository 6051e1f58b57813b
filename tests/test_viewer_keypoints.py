"""The viewer's keypoint overlay on a pose_estimation scene (procedural person), in the headless
browser of tests/test_viewer_browser.py: the skeleton is drawn where the metadata's visible
keypoints are, in the person's colour."""

import subprocess
import sys

import numpy as np
import pytest
from test_viewer_browser import ROOT, browser, open_scene, wait_for  # noqa: F401  (fixture)
from viewer_helpers import serving

from kubric.io.json_io import read_json

pytestmark = pytest.mark.blender
SCENE = "scene_00000003"


@pytest.fixture(scope="module")
def people(tmp_path_factory):
    out = tmp_path_factory.mktemp("viewer_people")
    cmd = [sys.executable, "-m", "kubric", "worker", "pose_estimation", "--seed", "3", "--out",
           str(out)]
    for option in ("resolution=64", "frame_end=2", "quality=draft", "max_num_people=1",
                   "character_source=procedural", "motion_source=procedural"):
        cmd += ["--set", option]
    done = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    return out


def test_keypoint_overlay_draws_the_visible_keypoints(browser, people):  # noqa: F811
    meta = read_json(people / SCENE / "metadata.json")
    person = meta["instances"][0]
    kp = np.asarray(person["keypoints_2d"][0])
    vis = np.asarray(person["keypoints_visibility"][0])
    assert (vis == 2).sum() >= 3
    with serving(people) as (address, _):
        open_scene(browser, f"http://{address[0]}:{address[1]}/", SCENE)
        box = browser.find_element("id", "overlay-keypoints")
        assert box.is_enabled()
        alpha = ("const c = document.getElementById('overlay-canvas');"
                 "return [c.width, Array.from(c.getContext('2d')"
                 ".getImageData(0, 0, c.width, c.height).data.filter((_, i) => i % 4 === 3))];")
        width, before = browser.execute_script(alpha)
        assert max(before) == 0                     # nothing drawn while the overlay is off
        box.click()
        width, after = wait_for(lambda: (lambda r: r if max(r[1]) > 0 else None)(
            browser.execute_script(alpha)), "the keypoint overlay")
    scale = width / 64
    drawn = np.asarray(after).reshape(-1, width) > 0
    for x, y in kp[vis == 2]:                        # a filled disc at every visible keypoint
        assert drawn[int(y * scale), int(x * scale)], (x, y)
    # nothing far from the keypoints (the skeleton joins them, so stay a disc away from all)
    rows, cols = np.nonzero(drawn)
    pts = kp[vis > 0] * scale
    gaps = np.min(np.hypot(cols[:, None] - pts[None, :, 0], rows[:, None] - pts[None, :, 1]),
                  axis=1)
    lines = np.zeros(len(rows), bool)
    for a, b in person["keypoint_skeleton"]:
        if vis[a - 1] and vis[b - 1]:
            p, q = kp[a - 1] * scale, kp[b - 1] * scale
            d = q - p
            t = np.clip(((cols - p[0]) * d[0] + (rows - p[1]) * d[1]) / max(d @ d, 1e-9), 0, 1)
            lines |= np.hypot(cols - p[0] - t * d[0], rows - p[1] - t * d[1]) < 4
    assert np.all(lines | (gaps < scale + 4))

"""The Blender backend under a rolling shutter (kubric.renderer.blender_rolling): Cycles' RGB rows
line up with the raycast backend's rolling segmentation (the exact layers it returns), against the
rows of a fast-moving white bar on black: per row the bar's horizontal centre in RGB and in the
segmentation agree within 1 px (0.5 px on average), while the global-shutter segmentation is up to
3 px away. And the
hybrid's refusals, one line each."""

import numpy as np
import pytest

import kubric as kb
from kubric.renderer.base import CapabilityError

pytestmark = pytest.mark.blender
pytest.importorskip("embreex")

W, H, D = 32, 24, 1.0


def _scene(duration=D):
    scene = kb.Scene(resolution=(W, H), frame_start=1, frame_end=2)
    cam = kb.PerspectiveCamera(focal_length=35, position=(0, -8, 0),
                               rolling_shutter_duration=duration)
    cam.look_at((0, 0, 0))
    scene += cam
    bar = kb.Cube(name="bar", scale=(0.4, 0.4, 2.0), segmentation_id=1,
                  material=kb.FlatMaterial(color=kb.Color(1, 1, 1)))
    scene += bar
    for f in range(0, 4):  # ~7 px per frame to the right
        bar.position = (-4.8 + 2.4 * f, 0, 0)
        bar.keyframe_insert("position", f)
    return scene


def _centres(mask):
    """(H,) mean column (pixel centres at +0.5) of each row's True pixels (NaN: none)."""
    cols = np.arange(mask.shape[1]) + 0.5
    count = mask.sum(1)
    with np.errstate(invalid="ignore"):
        return np.where(count > 0, (mask * cols).sum(1) / count, np.nan)


def test_cycles_rows_line_up_with_the_rolling_segmentation():
    from kubric.renderer.blender import Blender
    from kubric.renderer.raycast import Raycast
    scene = _scene()
    out = Blender(scene, samples_per_pixel=4, use_denoising=False).render(
        frames=[2], return_layers=("rgba", "segmentation"))
    rgb = out["rgba"][0, ..., :3].astype(float).mean(-1) / 255
    seg = out["segmentation"][0, ..., 0] == 1
    rows = np.flatnonzero(seg.sum(1) >= 2)
    assert len(rows) >= 12
    cols = np.arange(W) + 0.5
    lit = (rgb * cols).sum(1) / np.maximum(rgb.sum(1), 1e-9)  # intensity-weighted centre
    diff = np.abs(lit[rows] - _centres(seg)[rows])
    assert diff.max() < 1.0 and diff.mean() < 0.5  # Cycles reads rows d/(2H) late: ~0.15 px
    # the rows are skewed (the bar moved while they were read) and a global shutter is not this
    assert _centres(seg)[rows[-1]] - _centres(seg)[rows[0]] > 4.0
    scene.camera.rolling_shutter_duration = 0.0
    glob = Raycast(scene).render(frames=[2], return_layers=("segmentation",))
    glob_centres = _centres(glob["segmentation"][0, ..., 0] == 1)
    assert np.nanmax(np.abs(lit[rows] - glob_centres[rows])) > 2.0


def test_the_hybrid_refuses_motion_blur_and_characters_in_one_line():
    from kubric.assets.procedural_character import tube_person
    from kubric.renderer import blender_rolling
    scene = _scene()
    with pytest.raises(CapabilityError, match=r"^renderer=blender cannot render "
                                              r"motion_blur=0\.5 with a rolling shutter"):
        blender_rolling.check(scene, 0.5)
    scene += tube_person()
    with pytest.raises(CapabilityError, match=r"character 'person' under a rolling shutter"):
        blender_rolling.check(scene, 0.0)

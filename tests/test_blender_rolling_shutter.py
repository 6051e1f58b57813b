"""The Blender backend under a rolling shutter (kubric.renderer.blender_rolling), on a thin white
bar moving 17.5 px/frame to the right on black (48 × 16 px, readout d = 1 frame):

* Cycles' RGB rows are read at our row times t(r + 0.5) = f + d·((r + 0.5)/H − 1/2): per row, the
  bar's horizontal centre in linear RGB equals the pinhole projection (written out here) of the
  bar's centre at t(r + 0.5), −0.04 px on average (< v·d/(8H) = 0.14 px); rendered without the
  backend's half-row compensation, Cycles reads every row d/(2H) frames later (measured here:
  the mean offset is v·d/(2H) = 0.55 px ± 0.14 px), which is what the compensation removes;
* the RGB rows line up with the raycast backend's rolling segmentation (the exact layers it
  returns) within 1 px, and not with a global-shutter segmentation;
* a skinned character sliding 9 px/frame by its armature's root offset (a deformation, not an
  object motion): per row, the centre of Cycles' alpha lies on the rolling segmentation's
  (raycast: the mesh skinned at each row's time), 0.2 px on average, up to 3.9 px from the
  global-shutter segmentation's;
* the hybrid's refusals, one line each.
"""

import numpy as np
import pytest

import kubric as kb
from kubric.renderer.base import CapabilityError

pytestmark = pytest.mark.blender
pytest.importorskip("embreex")

W, H, D, F = 48, 16, 1.0, 2
SPEED = 3.0                # m/frame along +x
DEPTH = 8.0 - 0.01         # camera → the bar's front face (m)
FPX = 35.0 / 36.0 * W      # focal length in pixels (35 mm lens, 36 mm sensor width)
V = FPX * SPEED / DEPTH    # image speed (px/frame)


def _scene(duration=D):
    scene = kb.Scene(resolution=(W, H), frame_start=1, frame_end=3)
    cam = kb.PerspectiveCamera(focal_length=35, position=(0, -8, 0),
                               rolling_shutter_duration=duration)
    cam.look_at((0, 0, 0))
    scene += cam
    bar = kb.Cube(name="bar", scale=(0.25, 0.01, 3.0), segmentation_id=1,
                  material=kb.FlatMaterial(color=kb.Color(1, 1, 1)))
    scene += bar
    for f in range(0, 5):
        bar.position = (-4.5 + SPEED * f, 0, 0)
        bar.keyframe_insert("position", f)
    return scene


def _bar_column(t):
    """Pinhole image column of the bar's centre at time t (camera on −y looking along +y)."""
    return W / 2 + FPX * (-4.5 + SPEED * np.asarray(t)) / DEPTH


def _lit_centres(rgba):
    """(H,) per row the centre of the linear intensity (pixel centres at c + 0.5)."""
    srgb = rgba[..., :3].astype(float).mean(-1) / 255
    lin = np.where(srgb <= 0.04045, srgb / 12.92, ((srgb + 0.055) / 1.055) ** 2.4)
    return (lin * (np.arange(W) + 0.5)).sum(1) / np.maximum(lin.sum(1), 1e-9)


def _centres(mask):
    """(H,) mean column (pixel centres at +0.5) of each row's True pixels (NaN: none)."""
    cols = np.arange(mask.shape[1]) + 0.5
    count = mask.sum(1)
    with np.errstate(invalid="ignore"):
        return np.where(count > 0, (mask * cols).sum(1) / count, np.nan)


def _render(scene, **kwargs):
    from kubric.renderer.blender import Blender
    return Blender(scene, samples_per_pixel=8, use_denoising=False, **kwargs).render(
        frames=[F], return_layers=("rgba", "segmentation"))


ROW_TIMES = F + D * ((np.arange(H) + 0.5) / H - 0.5)


@pytest.fixture(scope="module")
def rendered():
    return _render(_scene())


def test_cycles_reads_each_row_at_its_row_time(rendered, monkeypatch):
    from kubric.renderer import blender_rolling
    offset = _lit_centres(rendered["rgba"][0]) - _bar_column(ROW_TIMES)
    assert np.abs(offset).max() < 0.5 and abs(offset.mean()) < V * D / (8 * H)
    # without the compensation Cycles reads each row half a row late (its own timing)
    monkeypatch.setattr(blender_rolling, "row_lead", lambda scene: 0.0)
    late = _lit_centres(_render(_scene())["rgba"][0]) - _bar_column(ROW_TIMES)
    assert abs(late.mean() - V * D / (2 * H)) < V * D / (8 * H)


def test_cycles_rows_line_up_with_the_rolling_segmentation(rendered):
    from kubric.renderer.raycast import Raycast
    lit = _lit_centres(rendered["rgba"][0])
    seg = rendered["segmentation"][0, ..., 0] == 1
    assert (seg.sum(1) >= 2).all()
    diff = np.abs(lit - _centres(seg))
    assert diff.max() < 1.0 and diff.mean() < 0.5
    # the rows are skewed (the bar moved while they were read) and a global shutter is not this
    assert _centres(seg)[-1] - _centres(seg)[0] > 0.8 * V * D
    scene = _scene(0.0)
    glob = Raycast(scene).render(frames=[F], return_layers=("segmentation",))
    glob_centres = _centres(glob["segmentation"][0, ..., 0] == 1)
    assert np.nanmax(np.abs(lit - glob_centres)) > 5.0


def _person_scene(duration=D):
    """A tube person (rest pose) sliding 0.6 m/frame along x by its root offset; 40 × 32 px."""
    from kubric.assets.procedural_character import tube_person
    scene = kb.Scene(resolution=(40, 32), frame_start=1, frame_end=3, frame_rate=12)
    person = tube_person(position=(0, 0.3, 0.0), segmentation_id=7)
    scene += person
    cam = kb.PerspectiveCamera(focal_length=50, position=(0.0, -3.4, 1.0),
                               rolling_shutter_duration=duration)
    cam.look_at((0.0, 0.0, 0.85))
    scene += cam
    for f in range(0, 5):
        person.root_offset = (0.6 * (f - 2), 0.0, 0.0)
        person.keyframe_insert("root_offset", f)
    return scene


def test_cycles_reads_a_skinned_character_row_by_row():
    from kubric.renderer.raycast import Raycast
    out = _render(_person_scene(), background_transparency=True)
    alpha = out["rgba"][0, ..., 3].astype(float) / 255
    seg = out["segmentation"][0, ..., 0] == 7
    rows = np.flatnonzero(seg.sum(1) >= 2)
    assert len(rows) > 20
    cols = np.arange(seg.shape[1]) + 0.5
    covered = (alpha * cols).sum(1) / np.maximum(alpha.sum(1), 1e-9)
    diff = np.abs(covered[rows] - _centres(seg)[rows])
    assert diff.max() < 1.0 and diff.mean() < 0.3
    glob = Raycast(_person_scene(0.0)).render(frames=[F], return_layers=("segmentation",))
    glob_diff = np.abs(covered[rows] - _centres(glob["segmentation"][0, ..., 0] == 7)[rows])
    assert glob_diff.mean() > 1.5 and glob_diff.max() > 3.0


def test_the_hybrid_refuses_motion_blur_and_depth_of_field_in_one_line():
    from kubric.renderer import blender_rolling
    scene = _scene()
    with pytest.raises(CapabilityError, match=r"^renderer=blender cannot render "
                                              r"motion_blur=0\.5 with a rolling shutter"):
        blender_rolling.check(scene, 0.5)
    scene.camera.use_dof = True
    with pytest.raises(CapabilityError, match=r"^renderer=blender cannot render depth of "
                                              r"field \(use_dof=True\) with a rolling shutter"):
        blender_rolling.check(scene, 0.0)

"""Cycles' RGB agrees with the exposure ground truth (kubric.annotations.exposure): the blur of an
out-of-focus edge is the disk of the defocus formula, and a moving object's motion-blurred
intensity is its exposure coverage from raycast sub-frames."""

import numpy as np
import pytest

import kubric as kb

pytestmark = pytest.mark.blender
pytest.importorskip("embreex")


def _linear(srgb):
    v = srgb.astype(float) / 255
    return np.where(v <= 0.04045, v / 12.92, ((v + 0.055) / 1.055) ** 2.4)


def _disk_cdf(u):
    """Fraction of a unit disk left of the vertical line x = u."""
    u = np.clip(u, -1.0, 1.0)
    return 0.5 + (u * np.sqrt(1.0 - u * u) + np.arcsin(u)) / np.pi


#: the plate scene's camera: focal length (mm), sensor width (mm), f-number, focus distance (m)
PLATE_LENS = (50.0, 36.0, 0.26, 10.0)


def plate_scene(w: int = 96, h: int = 64) -> kb.Scene:
    """A white plate 0.5 m wide facing a thin-lens camera (:data:`PLATE_LENS`) 1.75 m away,
    black world."""
    f_mm, sw, fstop, focus = PLATE_LENS
    scene = kb.Scene(resolution=(w, h), frame_start=0, frame_end=0)
    scene.camera = kb.PerspectiveCamera(position=(0, 0, 2), focal_length=f_mm, sensor_width=sw,
                                        use_dof=True, aperture_fstop=fstop,
                                        focus_distance=focus)
    scene += kb.Cube(scale=(0.25, 0.25, 0.001), position=(0, 0, 0.25),
                     material=kb.FlatMaterial(color=kb.Color(1, 1, 1)))
    return scene


def test_cycles_thin_lens_blurs_an_edge_by_the_defocus_diameter():
    from kubric.annotations.exposure import defocus
    from kubric.renderer.blender import Blender
    scene = plate_scene()
    w, h, f_mm, sw, fstop, focus = (*scene.resolution, *PLATE_LENS)
    out = Blender(scene, samples_per_pixel=256, use_denoising=False).render(
        return_layers=("rgba", "z"))
    row = _linear(out["rgba"][0, h // 2, :, 0])
    z = 2.0 - 0.251
    fx = f_mm / sw * w
    d_expected = f_mm * 1e-3 / fstop * abs(1 / z - 1 / focus) * fx  # the formula, by hand
    plate = out["z"][0, h // 2, :, 0] < 100
    layer = defocus(scene.camera, out["z"])[0, h // 2, :, 0]
    np.testing.assert_allclose(layer[plate], d_expected, rtol=1e-4)
    assert 10 < d_expected < 14
    # the pinhole image of the plate spans |x − W/2| < a px; a disk of diameter D blurs it to
    # the fraction of the disk over the plate
    a = 0.25 / z * fx
    x = np.arange(w) + 0.5 - w / 2

    def profile(d):
        r = d / 2
        return _disk_cdf((a - x) / r) - _disk_cdf((-a - x) / r)

    candidates = np.linspace(0.5 * d_expected, 1.5 * d_expected, 101)
    errors = [np.abs(row - profile(d)).mean() for d in candidates]
    best = candidates[int(np.argmin(errors))]
    assert abs(best - d_expected) < 0.08 * d_expected, (best, d_expected)
    assert np.abs(row - profile(d_expected)).max() < 0.1
    # without the lens the edge is sharp (the exact layers stay pinhole either way)
    scene.camera.use_dof = False
    sharp = _linear(Blender(scene, samples_per_pixel=16, use_denoising=False).render(
        return_layers=("rgba",))["rgba"][0, h // 2, :, 0])
    assert ((sharp > 0.05) & (sharp < 0.95)).sum() <= 4


def test_motion_blurred_rgb_is_the_exposure_coverage():
    from kubric.annotations.exposure import coverage_archive, coverage_fractions
    from kubric.renderer.blender import Blender
    from kubric.renderer.raycast_subframes import shutter_segmentation
    w, h, shutter = 96, 24, 0.75
    scene = kb.Scene(resolution=(w, h), frame_start=1, frame_end=3)
    scene.camera = kb.OrthographicCamera(position=(0, 0, 10), orthographic_scale=w / 10)
    cube = kb.Cube(scale=0.5, material=kb.FlatMaterial(color=kb.Color(1, 1, 1)))
    scene += cube
    for f in (1, 2, 3):  # 20 px per frame to the right
        cube.position = (-2.0 + 2.0 * (f - 1), 0.0, 0.0)
        cube.keyframe_insert("position", f)
    rgb = Blender(scene, samples_per_pixel=128, use_denoising=False, motion_blur=shutter).render(
        frames=[2], return_layers=("rgba",))["rgba"][0, h // 2, :, 0]
    archive = coverage_archive(shutter_segmentation(scene, [2], shutter, 64), shutter)
    label = scene.assets.index(cube) + 1
    coverage = coverage_fractions(archive, label, (1, h, w))[0, h // 2]
    assert ((coverage > 0) & (coverage < 1)).sum() >= 12  # 15 px of blur on each side
    # Cycles' box shutter centred on the frame = the coverage (1.5 px pixel filter, noise)
    assert np.abs(_linear(rgb) - coverage).max() < 0.12
    assert np.abs(_linear(rgb) - coverage).mean() < 0.02
    # a shutter that opened at the frame time (START) would be 7.5 px off
    shifted = np.roll(coverage, 7)
    assert np.abs(_linear(rgb) - shifted).max() > 0.3

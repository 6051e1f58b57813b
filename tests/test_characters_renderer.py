"""Characters in Blender: skinning, flow, object coordinates and segmentation against the model."""

import numpy as np
import pytest

import kubric as kb
from kubric.annotations.surfaces import ray_triangles
from kubric.core import camera_geometry as geo
from tests.character_fixtures import KINDS, RES, pixel_centres, walking_scene

pytestmark = pytest.mark.blender


def _blender(scene):
    from kubric.renderer.blender import Blender
    return Blender(scene, samples_per_pixel=1, use_denoising=False)


@pytest.mark.parametrize("kind", KINDS)
def test_blender_evaluated_mesh_equals_model_skinning(kind):
    from kubric.renderer.blender_characters import evaluated_vertices
    scene, person = walking_scene(kind=kind)
    renderer = _blender(scene)
    moved = 0.0
    for f in scene.frames:
        model = person.deformed_vertices(f)
        blender = evaluated_vertices(renderer, person, f)
        assert blender.shape == model.shape
        rendered = person.rendered_vertices
        assert np.abs(blender - model)[rendered].max() < 1e-5, f
        moved = max(moved, np.abs(model - person.deformed_vertices(1)).max())
    assert moved > 0.05  # the clip really deforms the mesh


def _surface_hits(scene, person, frame):
    """(pixel mask, triangle, barycentric) of the rays through every pixel centre that hit the
    person's deformed mesh at ``frame`` (the model's own ray cast)."""
    o, d = geo.pixel_rays(scene.camera, pixel_centres(RES, RES), frame=frame)
    tris = person.deformed_vertices(frame)[person.faces]
    tri, bary = np.full((RES, RES), -1), np.zeros((RES, RES, 3))
    # in tiles of 8×8 pixels, each against the triangles whose bounding sphere meets the cone of
    # the tile's rays (a pinhole's rays share one origin): the hits of all triangles, found faster
    centre = tris.mean(axis=1)
    radius = np.linalg.norm(tris - centre[:, None], axis=-1).max(axis=1)
    for r, c in np.ndindex(RES // 8, RES // 8):
        tile = np.s_[8 * r:8 * r + 8, 8 * c:8 * c + 8]
        oo, dd = o[tile].reshape(-1, 3), d[tile].reshape(-1, 3)
        assert np.allclose(oo, oo[0])
        dd = dd / np.linalg.norm(dd, axis=-1, keepdims=True)
        axis = dd.mean(axis=0) / np.linalg.norm(dd.mean(axis=0))
        spread = np.arccos(np.clip(dd @ axis, -1, 1)).max()
        to = centre - oo[0]
        dist = np.linalg.norm(to, axis=-1)
        off_axis = np.arccos(np.clip(to @ axis / dist, -1, 1))
        near = (dist <= radius) | (off_axis - np.arcsin(np.clip(radius / dist, 0, 1))
                                   <= spread + 1e-9)
        cand = np.flatnonzero(near)
        if cand.size:
            hit, weights, _ = ray_triangles(oo, dd, tris[cand])
            tri[tile] = np.where(hit >= 0, cand[hit], -1).reshape(8, 8)
            bary[tile] = weights.reshape(8, 8, 3)
    return tri, bary


@pytest.mark.parametrize("kind", KINDS)
def test_flow_object_coordinates_and_segmentation_follow_the_skinned_surface(kind):
    scene, person = walking_scene(kind=kind)
    out = _blender(scene).render(return_layers=("forward_flow", "backward_flow", "segmentation",
                                                "object_coordinates", "depth"))
    label = scene.assets.index(person) + 1
    errors, oc_errors, moving = [], [], []
    for i, f in enumerate(scene.frames):
        tri, bary = _surface_hits(scene, person, f)
        seg = out["segmentation"][i, ..., 0] == label
        ours = tri >= 0
        # segmentation: the character's pixels are where the model's ray cast hits it (pixels
        # whose ray grazes a silhouette edge may differ)
        assert (seg != ours).sum() <= max(3, 0.02 * ours.sum()), f
        sel = seg & ours
        assert sel.sum() > 150
        centres = pixel_centres(RES, RES)[sel]
        for other, layer in ((f + 1, "forward_flow"), (f - 1, "backward_flow")):
            if other not in scene.frames:
                continue
            pts = person.surface_points(tri[sel], bary[sel], other)
            xy, _ = geo.project_to_pixels(scene.camera, pts, frame=other)
            expected = np.stack([xy[:, 1] - centres[:, 1], xy[:, 0] - centres[:, 0]], -1)
            errors.append(np.linalg.norm(out[layer][i][sel] - expected, axis=-1))
            moving.append(np.linalg.norm(expected, axis=-1))
        # object coordinates: the rest-pose surface point, normalised to the rest bounds
        rest = person.surface_points(tri[sel], bary[sel], space="rest")
        lo, hi = person.rest_bounds
        oc_errors.append(np.abs(out["object_coordinates"][i][sel] - (rest - lo) / (hi - lo)))
    err = np.concatenate(errors)
    print(f"flow error px: median {np.median(err):.2e} p95 {np.percentile(err, 95):.2e} "
          f"max {err.max():.2e}; flow median {np.median(np.concatenate(moving)):.2f} px")
    assert np.median(np.concatenate(moving)) > 0.3   # the surface really moves in the image
    assert np.median(err) < 1e-3, np.median(err)
    assert np.percentile(err, 95) < 1e-2, np.percentile(err, 95)
    oc = np.concatenate(oc_errors)
    assert np.median(oc) < 1e-5 and np.percentile(oc, 99) < 1e-3, (np.median(oc), oc.max())


def test_rigid_object_coordinates_unchanged_beside_a_character():
    """The annotation material switches to the rest attribute only on character meshes."""
    scene, person = walking_scene(frames=1, moving_camera=False)
    cube = kb.Cube(position=(-0.9, -0.5, 0.4), scale=0.3)
    scene += cube
    out = _blender(scene).render(return_layers=("object_coordinates", "segmentation", "depth"))
    label = scene.assets.index(cube) + 1
    sel = out["segmentation"][0, ..., 0] == label
    assert sel.sum() > 20
    pts = geo.unproject_pixels(scene.camera, pixel_centres(RES, RES)[sel],
                               out["depth"][0, ..., 0][sel], frame=1)
    expected = ((pts - cube.position) / 0.3 + 1) / 2
    assert np.median(np.abs(out["object_coordinates"][0][sel] - expected)) < 1e-3

"""The character scene model (no engine): skinning, poses, clips, validation."""

import numpy as np
import pytest

import kubric as kb
from kubric.annotations.surfaces import ray_triangles
from kubric.assets.procedural_character import tube_person, walk_clip


def _rot(axis, angle):
    return np.asarray(kb.Quaternion(axis=axis, angle=angle))


def test_exported_and_rest_pose_is_identity():
    person = tube_person()
    assert kb.Character is type(person) and kb.MotionClip is type(walk_clip())
    np.testing.assert_allclose(person.deformed_vertices(), person.vertices, atol=1e-12)
    np.testing.assert_allclose(person.bone_transforms()[:, :3, 3], person.bone_rest[:, :3, 3])
    assert person.static and len(person.keypoint_names) == 17


def test_elbow_bend_rotates_the_wrist_about_the_elbow():
    """Independent derivation: bending the forearm by θ about its local x axis turns everything
    the forearm carries (the wrist ring) about the elbow by θ about that axis in the model."""
    person = tube_person()
    j = person.bone_index("LeftForeArm")
    theta = 1.1
    wrist_rest = person.keypoints(space="model")[person.keypoint_names.index("left_wrist")]
    rot = np.tile([1.0, 0, 0, 0], (person.num_bones, 1))
    rot[j] = _rot((1, 0, 0), theta)
    person.bone_rotations = rot
    elbow = person.bone_rest[j, :3, 3]
    axis = person.bone_rest[j, :3, 0]
    expected = elbow + kb.Quaternion(axis=axis, angle=theta).rotate(wrist_rest - elbow)
    got = person.keypoints(space="model")[person.keypoint_names.index("left_wrist")]
    np.testing.assert_allclose(got, expected, atol=1e-9)
    # the shoulder (on the upper arm) does not move; the hand bone's head is the wrist joint
    sh = person.keypoint_names.index("left_shoulder")
    np.testing.assert_allclose(person.keypoints(space="model")[sh],
                               person.bone_rest[person.bone_index("LeftArm"), :3, 3], atol=1e-9)
    np.testing.assert_allclose(person.posed_bones()[person.bone_index("LeftHand"), :3, 3],
                               elbow + kb.Quaternion(axis=axis, angle=theta).rotate(
                                   person.bone_rest[j + 1, :3, 3] - elbow), atol=1e-9)


def test_object_pose_and_root_offset_apply_after_skinning():
    person = tube_person(position=(1, 2, 3), euler=(0, 0, 0.7), scale=2.0)
    person.root_offset = (0.1, -0.2, 0.05)
    q = kb.Quaternion(person.quaternion)
    expected = q.rotate((person.vertices + [0.1, -0.2, 0.05]) * 2.0) + [1, 2, 3]
    np.testing.assert_allclose(person.deformed_vertices(), expected, atol=1e-5)
    box = person.aabb()
    assert np.allclose(box[0], expected[person.rendered_vertices].min(0), atol=1e-5)
    corners = person.bbox_3d
    assert corners.shape == (8, 3)
    assert np.all(corners.min(0) <= box[0] + 1e-5) and np.all(corners.max(0) >= box[1] - 1e-5)


def test_surface_points_blend_the_skinned_corners():
    person = tube_person()
    person.play(walk_clip(), start_frame=0, end_frame=6, frame_rate=12)
    rng = np.random.RandomState(1)
    tri = rng.randint(0, len(person.faces), 50)
    bary = rng.dirichlet([1, 1, 1], 50)
    verts = person.deformed_vertices(4)
    expected = np.einsum("ni,nij->nj", bary, verts[person.faces[tri]])
    np.testing.assert_allclose(person.surface_points(tri, bary, 4), expected, atol=1e-12)
    np.testing.assert_allclose(person.surface_points(tri, bary, space="rest"),
                               np.einsum("ni,nij->nj", bary, person.vertices[person.faces[tri]]))


def test_bone_rotation_keys_interpolate_by_nlerp_on_the_short_arc():
    person = tube_person()
    j = person.bone_index("Spine")
    for f, angle, sign in ((0, 0.0, 1), (2, 1.0, -1)):   # the second key stored as −q
        rot = np.tile([1.0, 0, 0, 0], (person.num_bones, 1))
        rot[j] = sign * _rot((1, 0, 0), angle)
        person.bone_rotations = rot
        person.keyframe_insert("bone_rotations", f)
    mid = person.get_value_at("bone_rotations", 1)[j]
    assert abs(abs(np.dot(mid, _rot((1, 0, 0), 0.5))) - 1) < 1e-6


def test_play_resamples_the_clip_to_the_scene_rate():
    clip = walk_clip(seconds=1.0, fps=30)
    scene = kb.Scene(frame_start=1, frame_end=5, frame_rate=10)
    person = tube_person()
    scene += person
    person.play(clip)
    assert sorted(person.keyframes["bone_rotations"]) == [1, 2, 3, 4, 5]
    # frame 3 = 0.2 s = clip sample 6 exactly
    j = person.bone_index(clip.bone_names[0])
    np.testing.assert_allclose(person.get_value_at("bone_rotations", 3)[j],
                               clip.rotations[6, 0], atol=1e-6)
    np.testing.assert_allclose(person.get_value_at("root_offset", 3), clip.root_offsets[6],
                               atol=1e-6)
    # bones the clip does not name stay at rest
    assert np.allclose(person.get_value_at("bone_rotations", 3)[person.bone_index("Head")],
                       [1, 0, 0, 0])


def _rig_kwargs():
    p = tube_person()
    return dict(vertices=p.vertices, faces=p.faces, bone_names=p.bone_names,
                bone_parents=p.bone_parents, bone_rest=p.bone_rest, bone_tails=p.bone_tails,
                skin_indices=p.skin_indices, skin_weights=p.skin_weights)


@pytest.mark.parametrize("change,message", [
    (lambda k: k.update(skin_weights=np.zeros_like(k["skin_weights"])), "has no skin weights"),
    (lambda k: k["skin_weights"].__setitem__((0, slice(None)), 0), "without weight"),
    (lambda k: k.update(bone_parents=[-1, -1] + list(k["bone_parents"][2:])), "bone_parents"),
    (lambda k: k["bone_tails"].__setitem__(3, k["bone_tails"][3] + [0, 0, 0.1]), "LeftArm"),
    (lambda k: k["vertices"].__setitem__((2, 1), np.nan), "NaN"),
    (lambda k: k.update(faces=k["faces"] + 10**6), "faces holds"),
    (lambda k: k.update(bone_names=["Hips"] * len(k["bone_names"])), "repeats"),
])
def test_bad_rigs_get_one_line(change, message):
    kwargs = {k: np.array(v) if not isinstance(v, list) else list(v)
              for k, v in _rig_kwargs().items()}
    change(kwargs)
    with pytest.raises(ValueError, match=message) as err:
        kb.Character(name="bad", **kwargs)
    assert "\n" not in str(err.value) and "'bad'" in str(err.value)


def test_bad_clips_get_one_line():
    clip = walk_clip()
    rot = clip.rotations.copy()
    rot[3, 1, 2] = np.nan
    with pytest.raises(ValueError, match=r"NaN or inf at sample 3, joint 'LeftLeg'"):
        kb.MotionClip(clip.bone_names, 30, rot, clip.root_offsets, name="walk")
    alien = kb.MotionClip(["Neck", "Tail"], 30, np.tile([1.0, 0, 0, 0], (2, 2, 1)),
                          np.zeros((2, 3)), name="alien")
    with pytest.raises(ValueError, match=r"joints \['Neck', 'Tail'\] match no bone"):
        tube_person().play(alien, 0, 10, end_frame=3)
    with pytest.raises(ValueError, match="fps must be a positive number"):
        kb.MotionClip(clip.bone_names, 0, clip.rotations, clip.root_offsets)
    person = tube_person()
    with pytest.raises(ValueError, match="zero quaternion"):
        person.bone_rotations = np.zeros((person.num_bones, 4))


def test_ray_triangles_finds_the_nearest_hit():
    tris = np.array([[[0, 0, 1], [1, 0, 1], [0, 1, 1]], [[0, 0, 2], [1, 0, 2], [0, 1, 2]]], float)
    tri, bary, dist = ray_triangles([[0.2, 0.3, 5], [0.9, 0.9, 5]], [[0, 0, -1], [0, 0, -1]], tris)
    assert tri.tolist() == [1, -1] and dist[0] == pytest.approx(3.0) and np.isinf(dist[1])
    np.testing.assert_allclose(bary[0] @ tris[1], [0.2, 0.3, 2.0])


def test_keypoints_follow_the_walk():
    scene = kb.Scene(frame_start=1, frame_end=8, frame_rate=12)
    person = tube_person()
    scene += person
    person.play(walk_clip())
    kp = np.stack([person.keypoints(f) for f in scene.frames])
    ankle = person.keypoint_names.index("left_ankle")
    heads = np.stack([person.bone_transforms(f)[person.bone_index("LeftFoot"), :3, 3]
                      for f in scene.frames])
    assert np.abs(kp[:, ankle] - heads).max() < 0.005   # ring centroid vs joint
    assert np.ptp(kp[:, ankle, 1]) > 0.2                  # the person walks along −y


def test_coco_keypoints_use_pixel_index_coordinates():
    from kubric.annotations.keypoints import coco_keypoints
    flat, n = coco_keypoints([[10.5, 20.5], [3.25, 4.0], [-5.0, 2.0]], [2, 1, 0])
    assert flat == [10.0, 20.0, 2, 2.75, 3.5, 1, 0.0, 0.0, 0] and n == 2
    with pytest.raises(ValueError, match="needs"):
        coco_keypoints([[1, 2, 3]], [2])


def test_batched_bone_transforms_equal_frame_by_frame():
    scene = kb.Scene(frame_start=0, frame_end=6, frame_rate=12)
    person = tube_person(position=(1, 0, 0))
    scene += person
    person.play(walk_clip())
    person.position = (1, 2, 0)
    person.keyframe_insert("position", 6)
    frames = [0, 0.25, 1.5, 3.1, 6]
    batch = person.bone_transforms_at(frames)
    for f, b in zip(frames, batch, strict=True):
        np.testing.assert_allclose(b, person.bone_transforms(f), atol=1e-12)

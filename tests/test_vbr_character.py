"""vbr with a person (object_type=character, the procedural tube person): it flies and spins as
a rigid object would, performs its clip, and the LASR sequence and keypoints are written."""

import json

import numpy as np
import pytest
from collection_fixtures import run_worker

import kubric as kb
from kubric.recipes.vbr import key_free_flight

OPTIONS = ("resolution=48", "num_frames=4", "samples=1", "denoise=false",
           "object_type=character", "character_source=procedural", "motion_source=procedural")


@pytest.mark.blender
def test_vbr_person_scene(tmp_path):
    from kubric.docgen import undocumented_scene_fields
    run_worker("vbr", 2, tmp_path, OPTIONS)
    scene = tmp_path / "scene_00000002"
    assert undocumented_scene_fields(scene) == []
    meta = json.loads((scene / "metadata.json").read_text())
    assert meta["metadata"]["object_type"] == "character"
    assert meta["metadata"]["object_model"] == "tube_person/procedural_walk"
    (person,) = meta["instances"]
    assert np.asarray(person["keypoints_2d"]).shape == (4, 17, 2)
    assert (scene / "lasr").is_dir()
    # it moves: the keypoints' centre travels between the first and last frame
    kp = np.asarray(person["keypoints_3d"])
    assert np.linalg.norm(kp[-1].mean(0) - kp[0].mean(0)) > 0.01


def test_free_flight_keys_match_constant_velocity_and_spin():
    scene = kb.Scene(frame_start=1, frame_end=4, frame_rate=10)
    obj = kb.Cube(position=(1, 2, 3), velocity=(0.5, 0, -1), angular_velocity=(0, 0, 2.0))
    scene += obj
    key_free_flight(scene, obj)
    np.testing.assert_allclose(obj.get_value_at("position", 5), (1.25, 2, 2.5), atol=1e-6)
    q = kb.Quaternion(obj.get_value_at("quaternion", 5))
    assert q.angle == pytest.approx(1.0, abs=1e-5)       # 2 rad/s × 0.5 s about z
    assert np.allclose(q.axis, (0, 0, 1), atol=1e-5)
    assert np.allclose(obj.velocity, 0)


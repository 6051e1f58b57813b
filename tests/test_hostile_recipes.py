"""Round three (issue 41): impossible recipe options and mixed-up sources refused in one line
before rendering — svr's object_size larger than the camera distance, nvs's min_num_objects that
cannot stand in its region, a motion source given as character_source (and the reverse), and
pose_estimation with a character that has no keypoints. Real asset sources on disk, the real
``kubric worker`` in a subprocess."""

import os
import pathlib
import subprocess
import sys
import time

import numpy as np
import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]


def worker(recipe, out, *sets, timeout=300):
    env = dict(os.environ, PYTHONPATH=f"{ROOT}{os.pathsep}{os.environ.get('PYTHONPATH', '')}")
    args = [a for s in sets for a in ("--set", s)]
    return subprocess.run([sys.executable, "-m", "kubric", "worker", recipe, "--seed", "1",
                           "--out", str(out), *args], cwd=ROOT, env=env, capture_output=True,
                          text=True, timeout=timeout)


def one_line(proc, code, *words):
    lines = [ln for ln in proc.stderr.strip().splitlines()
             if not ln.startswith("pybullet build time")]  # PyBullet's own banner
    assert proc.returncode == code and "Traceback" not in proc.stderr, proc.stderr[-3000:]
    assert len(lines) == 1, proc.stderr[-3000:]
    for word in words:
        assert word in lines[0], lines[0]


@pytest.fixture(scope="module")
def sources(tmp_path_factory):
    """A motion source (one clip) and a character source whose character has no keypoint
    regressor (the tube person's rig without it), written by the asset writers."""
    from kubric.asset_tools.character_writer import package_character, package_motion
    from kubric.asset_tools.writer import write_manifest
    from kubric.assets.procedural_character import tube_person
    root = tmp_path_factory.mktemp("people")
    clip = package_motion("wave", root / "motions", rotations=np.tile(np.eye(3), (4, 1, 1, 1)),
                          root_offsets=np.zeros((4, 3)),
                          info={"name": "wave", "bone_names": ["root"], "fps": 24}, files={},
                          license="CC0", metadata={"category": "motion"})
    write_manifest(root / "motions" / "manifest.json", "Motions", "1", {"wave": clip})
    person = tube_person()
    arrays = {k: getattr(person, k) for k in ("vertices", "faces", "bone_parents", "bone_rest",
                                              "bone_tails", "skin_indices", "skin_weights")}
    info = {"rig": "tube", "bone_names": person.bone_names, "keypoint_names": []}
    entry = package_character("no_keypoints", root / "characters", arrays=arrays, info=info,
                              files={}, license="CC0", metadata={"category": "character"})
    write_manifest(root / "characters" / "manifest.json", "Characters", "1",
                   {"no_keypoints": entry})
    return root


def test_svr_object_larger_than_the_camera_distance_is_refused(tmp_path):
    one_line(worker("svr", tmp_path / "o", "object_size=1e30"), 2,
             "object_size=1e+30 m must be smaller than the nearest camera distance 2.5 m")
    assert not (tmp_path / "o").exists()


def test_nvs_objects_that_cannot_stand_in_the_region_are_refused(tmp_path):
    start = time.monotonic()
    proc = worker("nvs", tmp_path / "o", "min_num_objects=50", "max_num_objects=50",
                  "region=0.3", "renderer=raycast", "resolution=32x24")
    one_line(proc, 2, "fewer than min_num_objects=50", "raise region")
    assert time.monotonic() - start < 120  # refused before rendering
    assert not list((tmp_path / "o").glob("scene_*"))


def test_a_motion_source_as_character_source_and_the_reverse(sources, tmp_path):
    motions, characters = sources / "motions", sources / "characters"
    one_line(worker("pose_estimation", tmp_path / "a", f"character_source={motions}",
                    "motion_source=procedural"), 2,
             "character_source=", "holds ['MotionClip'] assets",
             "a motion source: give it as motion_source?")
    one_line(worker("pose_estimation", tmp_path / "b", "character_source=procedural",
                    f"motion_source={characters}"), 2,
             "motion_source=", "holds ['Character'] assets",
             "a character source: give it as character_source?")


def test_pose_estimation_refuses_a_character_without_keypoints_before_rendering(sources,
                                                                                 tmp_path):
    start = time.monotonic()
    proc = worker("pose_estimation", tmp_path / "o", f"character_source={sources / 'characters'}",
                  "motion_source=procedural", "resolution=32x24", "frame_end=2")
    one_line(proc, 2, "character 'no_keypoints' of character_source has no keypoint regressor")
    assert time.monotonic() - start < 120
    assert not list((tmp_path / "o").glob("scene_*"))


def test_character_and_motion_loaders_name_the_damaged_file(sources, tmp_path):
    from kubric.assets.characters import CharacterAssetError, character_kwargs, motion_kwargs
    good_npz = tmp_path / "motion.npz"
    np.savez(good_npz, rotations=np.tile(np.eye(3), (2, 1, 1, 1)), root_offsets=np.zeros((2, 3)))
    good_json = tmp_path / "motion.json"
    good_json.write_text('{"name": "w", "bone_names": ["root"], "fps": 24}')
    motion_kwargs(good_npz, good_json)  # the undamaged pair loads
    bad_npz, bad_json = tmp_path / "cut.npz", tmp_path / "bad.json"
    bad_npz.write_bytes(good_npz.read_bytes()[:40])
    bad_json.write_text('{"name": ')
    for load in (character_kwargs, motion_kwargs):
        with pytest.raises(CharacterAssetError, match=f"{bad_npz} is not a readable .npz"):
            load(bad_npz, good_json)
    with pytest.raises(CharacterAssetError, match=f"{bad_json} is not valid JSON"):
        motion_kwargs(good_npz, bad_json)

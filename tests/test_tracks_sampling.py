"""Query sampling, option checks before rendering, tracks.npz round trip (no rendering)."""

import subprocess
import sys

import numpy as np
import pytest

from kubric.annotations import tracks as tr
from kubric.annotations.track_files import read_tracks, write_tracks
from kubric.datasets.exports.tapvid import tapvid_example
from kubric.pipeline import OptionError, get_recipe


def _groups():
    """8 frames of 32×32: background 0, a large object 1, a small object 2, sky −1."""
    g = np.zeros((8, 32, 32), dtype=np.int32)
    g[:, 4:20, 4:20] = 1
    g[:, 24:28, 24:28] = 2
    g[:, :2, :] = -1
    return g


def test_allocation_is_tapvid_balanced_with_cap_and_shortfall_fill():
    # equal shares, capped at 10% of each group's grid points
    np.testing.assert_array_equal(tr.allocate([1000, 1000, 1000], 30, 0.1), [10, 10, 10])
    # the small group is capped (10% of 20 = 2); the rest is shared by the others
    np.testing.assert_array_equal(tr.allocate([20, 1000, 1000], 30, 0.1), [2, 14, 14])
    # caps too tight for the total: the shortfall comes from the group with most left
    np.testing.assert_array_equal(tr.allocate([20, 100, 1000], 300, 0.1), [2, 10, 288])
    with pytest.raises(ValueError, match="more than the 1120 trackable"):
        tr.allocate([20, 100, 1000], 2000, 0.1)


def test_sample_queries_exact_count_balanced_deterministic():
    g = _groups()
    q = tr.sample_queries(g, 40, np.random.RandomState(1), stride=2)
    assert q.shape == (40, 3) and q.dtype == np.float32
    again = tr.sample_queries(g, 40, np.random.RandomState(1), stride=2)
    np.testing.assert_array_equal(q, again)
    assert not np.array_equal(q, tr.sample_queries(g, 40, np.random.RandomState(2), stride=2))
    # pixel centres, on one stride-2 grid, never on sky, no duplicates
    np.testing.assert_array_equal(q[:, 1:] % 1, 0.5)
    assert len({tuple(v % 2) for v in q[:, 0:1].astype(int)}) == 1
    labels = g[q[:, 0].astype(int), q[:, 1].astype(int), q[:, 2].astype(int)]
    assert (labels >= 0).all() and len(np.unique(q, axis=0)) == 40
    counts = np.bincount(labels, minlength=3)
    assert counts[2] == 2   # 8 grid points on the small object × 0.1, rounded... at most 10 %
    assert abs(int(counts[0]) - int(counts[1])) <= 1


def test_check_queries_one_line_errors():
    tr.check_queries([[0, 0.5, 0.5], [3, 31.9, 0]], 4, 32, 32)
    for bad, what in (([[4, 1, 1]], "t must be an integer in \\[0, 4\\)"),
                      ([[1.5, 1, 1]], "outside the clip"), ([[0, -1, 1]], "y in"),
                      ([[0, 1, 32]], "x in"), ([[0, 1]], "shape")):
        with pytest.raises(ValueError, match=what):
            tr.check_queries(bad, 4, 32, 32)


BASE = ["resolution=32", "frame_end=4"]


@pytest.mark.parametrize("options,message", [
    (["tracks=-1"], "option tracks='-1': out of range"),
    (["tracks=65"], r"tracks=65 is more than the 64 query points available \(4 frames × 32×32"),
])
def test_bad_track_options_fail_before_rendering(options, message):
    with pytest.raises(OptionError, match=message):
        get_recipe("movi_a").from_assignments(BASE + options)


def test_given_queries_checked_before_rendering(tmp_path):
    good = tmp_path / "q.txt"
    good.write_text("0 10.5 3.5\n3, 1.5, 31.5\n")
    recipe = get_recipe("movi_e").from_assignments(BASE + [f"track_queries={good}"])
    assert recipe._queries.shape == (2, 3)
    outside = tmp_path / "outside.npy"
    np.save(outside, np.array([[0, 1.0, 1.0], [4, 1.0, 1.0]]))
    with pytest.raises(OptionError, match=r"query 1 .* is outside the clip"):
        get_recipe("movi_e").from_assignments(BASE + [f"track_queries={outside}"])
    with pytest.raises(OptionError, match="not both"):
        get_recipe("movi_c").from_assignments(BASE + [f"track_queries={good}", "tracks=4"])
    # the command line: exit 2, one line on stderr, nothing written
    np.save(outside, np.array([[0, 1.0, 1.0], [24, 1.0, 1.0]]))  # frames 1..24 → t in [0, 24)
    proc = subprocess.run([sys.executable, "-m", "kubric", "worker", "movi_a", "--seed", "0",
                           "--out", str(tmp_path / "out"), "--set", "resolution=32",
                           "--set", f"track_queries={outside}"],
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2 and len(proc.stderr.strip().splitlines()) == 1, proc.stderr
    assert not (tmp_path / "out").exists()


def test_tracks_file_round_trip_and_tapvid_layout(tmp_path):
    rng = np.random.RandomState(0)
    n, t, w, h = 5, 3, 8, 6
    tracks = {"query_points": rng.rand(n, 3).astype(np.float32),
              "target_points": (rng.rand(n, t, 2) * [w, h]).astype(np.float32),
              "occluded": rng.rand(n, t) > 0.5, "occlusion_reason": np.zeros((n, t), np.uint8),
              "visible": rng.rand(n, t).astype(np.float32),
              "depth": rng.rand(n, t).astype(np.float32),
              "points_world": rng.rand(n, t, 3).astype(np.float32),
              "points_camera": rng.rand(n, t, 3).astype(np.float32),
              "points_object": rng.rand(n, 3), "instance_id": np.arange(n, dtype=np.int32),
              "is_foreground": np.arange(n) > 0, "frames": np.arange(1, t + 1, dtype=np.int32),
              "resolution": np.array([w, h], np.int32), "pixel_offset": np.float32(0.5),
              "depth_tolerance": np.float32(1e-3)}
    path = write_tracks(tracks, tmp_path / "s" / "tracks.npz")
    assert [p.name for p in path.parent.iterdir()] == ["tracks.npz"]  # no temporary left
    back = read_tracks(path.parent)
    for k, v in tracks.items():
        np.testing.assert_array_equal(back[k], v)
        assert back[k].dtype == np.asarray(v).dtype
    ex = tapvid_example(back, np.zeros((t, h, w, 4), np.uint8))
    assert ex["video"].shape == (t, h, w, 3)
    np.testing.assert_allclose(ex["points"] * [w, h], tracks["target_points"], rtol=1e-6)
    with pytest.raises(ValueError, match="does not match"):
        tapvid_example(back, np.zeros((t, h + 1, w, 3), np.uint8))
    with pytest.raises(FileNotFoundError, match="tracks=N"):
        read_tracks(tmp_path)


def test_track_option_limit_is_the_grid():
    assert tr.grid_points_available(4, 32, 32, 4) == 64
    assert tr.grid_points_available(5, 30, 32, 4) == 1 * 7 * 8  # offsets 1..3 of 5 frames → 1
    get_recipe("movi_a").from_assignments(BASE + ["tracks=64"])


def test_draw_tracks_filled_visible_hollow_occluded_trails():
    from kubric.pipeline.inspect import draw_tracks, marker_radius, track_colours
    frames = np.zeros((3, 40, 60, 3), np.uint8)
    tracks = {"target_points": np.array([[[10.5, 10.5], [14.5, 10.5], [18.5, 10.5]],
                                         [[40.5, 30.5], [40.5, 30.5], [40.5, 30.5]],
                                         [[-5.0, 5.0], [-5.0, 5.0], [-5.0, 5.0]]], np.float32),
              "occluded": np.array([[False, False, False], [True, True, True],
                                    [True, True, True]]),
              "occlusion_reason": np.array([[0, 0, 0], [4, 4, 4], [2, 2, 2]], np.uint8)}
    out = draw_tracks(frames, tracks)
    c = track_colours(3).astype(int)
    r = marker_radius(60)
    assert np.array_equal(out[2, 10, 18], c[0])                  # filled disc, visible
    assert np.array_equal(out[2, 10, 13], c[0])                  # its trail from frame 0
    assert not np.array_equal(out[0, 10, 13], c[0])              # no trail at frame 0
    assert np.array_equal(out[1, 30, 40], [0, 0, 0])             # hollow ring, occluded
    ring = out[1, 30 - int(r) - 1:30 + int(r) + 2, 40 - int(r) - 1:40 + int(r) + 2]
    assert (np.abs(ring - c[1]).max(axis=-1) == 0).sum() >= 4
    assert not (np.abs(out - c[2]).max(axis=-1) == 0).any()     # outside: not drawn
    assert not np.shares_memory(out, frames) and frames.max() == 0


def test_point_leaving_the_image_and_going_behind_the_camera():
    """Synthetic layers (no render): a static background point seen at frame 0 while the camera
    turns away: inside → outside the image → behind the camera."""
    import kubric as kb
    w, h = 16, 12
    scene = kb.Scene(resolution=(w, h), frame_start=0, frame_end=2)
    cam = kb.PerspectiveCamera(position=(0, 0, 0))
    scene.camera = cam
    for f, target in enumerate([(0, 5, 0), (5, 1, 0), (0, -5, 0)]):
        cam.look_at(target)
        cam.keyframe_insert("quaternion", f)
    wall = kb.Cube(name="wall", background=True)
    scene += wall
    label = int(tr.instance_labels(scene.assets)[scene.assets.index(wall)])
    seg = np.full((3, h, w), label)
    depth = np.full((3, h, w), 5.0, np.float32)
    out = tr.compute_tracks(cam, [0, 1, 2], depth, seg, scene.assets, [[0, 6.5, 8.5]])
    np.testing.assert_allclose(out["target_points"][0, 0], [8.5, 6.5], atol=1e-5)
    # (behind the camera, the projection is mirrored: it may or may not land in the image)
    np.testing.assert_array_equal(out["occlusion_reason"][0, :2], [0, tr.OUTSIDE_IMAGE])
    assert out["occlusion_reason"][0, 2] & tr.BEHIND_CAMERA
    assert not out["occlusion_reason"][0, 2] & (tr.OTHER_INSTANCE | tr.DEPTH_CLOSER)
    assert out["points_camera"][0, 2, 2] > 0
    np.testing.assert_array_equal(out["occluded"][0], [False, True, True])
    np.testing.assert_array_equal(out["visible"][0], [1.0, 0.0, 0.0])
    assert out["instance_id"][0] == 0 and not out["is_foreground"][0]
    np.testing.assert_allclose(out["points_object"][0], out["points_world"][0, 0], atol=1e-6)
    with pytest.raises(ValueError, match="hits no surface"):
        tr.compute_tracks(cam, [0, 1, 2], depth, np.zeros_like(seg), scene.assets, [[0, 1, 1]])

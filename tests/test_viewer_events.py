"""The viewer's accumulated event frames (#37) and filled segmentation overlay (#40), served from
a synthetic scene whose ``events.h5`` holds events the test chose: each frame's picture is
checked against the test's own count of ON / OFF events per pixel in that frame's interval."""

import io

import numpy as np
import pytest
from PIL import Image
from viewer_helpers import H, T, W, get_json, request, serving, synthetic_scene

from kubric.io.event_h5 import encode_events
from kubric.io.palette import label_palette

pytest.importorskip("h5py")
RATE = 12  # the synthetic scene's frame_rate: frame i at i / 12 s
ON, OFF, BALANCED = (230, 57, 70), (69, 123, 237), (150, 150, 150)


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    """A synthetic scene plus an events.h5 of 400 random events over frames 0..T-1, and events
    placed exactly on the frame times (an interval is (t_{i-1}, t_i])."""
    directory = tmp_path_factory.mktemp("viewer_events") / "scene_00000003"
    directory.mkdir()
    synthetic_scene(directory)
    rng = np.random.default_rng(0)
    n = 400
    end = (T - 1) * 1e6 / RATE
    t = np.sort(np.round(rng.uniform(0, end, n)))
    x, y, p = rng.integers(0, W, n), rng.integers(0, H, n), rng.integers(0, 2, n)
    # on the boundaries: t_1 belongs to frame 1, one µs later to frame 2
    t1 = int(np.ceil(1e6 / RATE))
    extra = {"x": [0, 1], "y": [H - 1, H - 1], "t": [t1 - 1, t1 + 1], "p": [1, 0]}
    events = {k: np.concatenate([v, extra[k]]) for k, v in (("x", x), ("y", y), ("t", t),
                                                             ("p", p))}
    order = np.argsort(events["t"], kind="stable")
    events = {k: np.asarray(v)[order] for k, v in events.items()}
    events = {"x": events["x"].astype(np.uint16), "y": events["y"].astype(np.uint16),
              "t": events["t"], "p": events["p"].astype(np.uint8)}
    (directory / "events.h5").write_bytes(encode_events(events, np.full((2, H, W), 0.2)))
    return directory.parent, events


def _random_events(seed: int, n: int) -> dict:
    rng = np.random.default_rng(seed)
    t = np.sort(np.round(rng.uniform(0, (T - 1) * 1e6 / RATE, n)))
    return {"x": rng.integers(0, W, n).astype(np.uint16), "y": rng.integers(0, H, n)
            .astype(np.uint16), "t": t, "p": rng.integers(0, 2, n).astype(np.uint8)}


def _expected(events: dict, i: int) -> np.ndarray:
    """Frame i's picture from the test's own count of ON / OFF events per pixel in its
    interval (t_{i-1}, t_i] (frame 0: t ≤ 0)."""
    lo, hi = (i - 1) * 1e6 / RATE, i * 1e6 / RATE
    inside = (events["t"] > lo) & (events["t"] <= hi) if i else events["t"] <= 0
    on = np.zeros((H, W), int)
    off = np.zeros((H, W), int)
    for x, y, p in zip(events["x"][inside], events["y"][inside], events["p"][inside],
                       strict=True):
        (on if p else off)[y, x] += 1
    expected = np.zeros((H, W, 3), np.uint8)
    expected[(on + off > 0) & (on == off)] = BALANCED
    expected[on > off] = ON
    expected[off > on] = OFF
    return expected


def test_a_rig_camera_s_event_frames_come_from_its_own_stream(tmp_path):
    """A stereo scene's events_right.h5 is the layer right_events (the rig view's right tile
    shows it when events is selected), drawn from that file, not from events.h5."""
    directory = tmp_path / "scene_00000004"
    synthetic_scene(directory)
    left, right = _random_events(1, 300), _random_events(2, 300)
    (directory / "events.h5").write_bytes(encode_events(left, np.full((2, H, W), 0.2)))
    (directory / "events_right.h5").write_bytes(encode_events(right, np.full((2, H, W), 0.2)))
    with serving(tmp_path) as (address, _):
        _, meta = get_json(address, "/api/scene/scene_00000004")
        assert meta["summary"]["layers"][-2:] == ["events", "right_events"]
        assert meta["layers"]["right_events"]["kind"] == "events"
        for i in range(T):
            got = _png(address, f"/api/frame/scene_00000004/right_events/{i}.png")
            np.testing.assert_array_equal(got, _expected(right, i), err_msg=f"frame {i}")
            assert i == 0 or (_expected(right, i) != _expected(left, i)).any()
        status, body = get_json(address, "/api/frame/scene_00000004/left_events/1.png")
        assert status == 404 and "camera 'left'" in body["error"]


def _png(address, target):
    status, ctype, body = request(address, target)
    assert status == 200 and ctype == "image/png", body[:300]
    return np.asarray(Image.open(io.BytesIO(body)).convert("RGB"))


def test_event_frames_accumulate_each_frame_interval(scene):
    folder, events = scene
    with serving(folder) as (address, _):
        _, meta = get_json(address, "/api/scene/scene_00000003")
        assert meta["summary"]["layers"][-1] == "events"
        assert meta["layers"]["events"]["kind"] == "events"
        for i in range(T):
            picture = _png(address, f"/api/frame/scene_00000003/events/{i}.png")
            np.testing.assert_array_equal(picture, _expected(events, i), err_msg=f"frame {i}")
        # the boundary events: t_1 - 1 µs (ON) in frame 1, t_1 + 1 µs (OFF) in frame 2
        assert tuple(_png(address, "/api/frame/scene_00000003/events/1.png")[H - 1, 0]) in (
            ON, BALANCED)
        assert tuple(_png(address, "/api/frame/scene_00000003/events/2.png")[H - 1, 1]) in (
            OFF, BALANCED)
        status, body = get_json(address, f"/api/frame/scene_00000003/events/{T}.png")
        assert status == 404 and f"0..{T - 1}" in body["error"]


def test_a_scene_without_events_has_no_event_layer(tmp_path):
    synthetic_scene(tmp_path / "scene_00000001")
    with serving(tmp_path) as (address, _):
        _, meta = get_json(address, "/api/scene/scene_00000001")
        assert "events" not in meta["summary"]["layers"]
        status, body = get_json(address, "/api/frame/scene_00000001/events/0.png")
        assert status == 404 and "events.h5" in body["error"]


def test_a_corrupt_events_file_is_named(tmp_path):
    synthetic_scene(tmp_path / "scene_00000001")
    (tmp_path / "scene_00000001" / "events.h5").write_bytes(b"not hdf5")
    with serving(tmp_path) as (address, _):
        status, body = get_json(address, "/api/frame/scene_00000001/events/1.png")
        assert status == 422 and "scene_00000001/events.h5 is unreadable" in body["error"]


def test_filled_segmentation_is_the_palette_on_objects_and_clear_elsewhere(scene):
    folder, _ = scene
    seg = np.asarray(Image.open(folder / "scene_00000003" / "segmentation_00001.png"))
    with serving(folder) as (address, _):
        status, _, body = request(address, "/api/frame/scene_00000003/fill/1.png")
    assert status == 200
    fill = np.asarray(Image.open(io.BytesIO(body)).convert("RGBA"))
    assert (fill[..., 3] == np.where(seg > 0, 255, 0)).all()
    palette = label_palette(2)
    assert (fill[seg == 1][:, :3] == palette[1]).all()

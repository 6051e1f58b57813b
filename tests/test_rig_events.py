"""Event cameras on a camera rig, on real output: a tiny stereo MOVi-A scene with ``events=true``
rendered by the raycast backend (bpy blocked), read back from its scene directory:

* the right camera's stream (``events_right.h5``) sums, between frame times, to the log-intensity
  change of the right camera's own RGB files (decoded here) at ≥ 95 % of pixels — and not to the
  left camera's;
* the left (reference) camera's stream is the mono scene's of the same seed, bit for bit; the
  right camera's thresholds are drawn apart from the left's;
* metadata names each camera's file and count; the scene packs with its own schema and the
  right stream comes back as ``cameras/right/event_stream/*``.
"""

import json

import numpy as np
import pytest

from kubric import file_io

pytest.importorskip("h5py")
pytest.importorskip("cv2")  # tests/test_rig.py's worker helper

from test_rig import _right_layers, _worker  # noqa: E402

W, H, RATE = 64, 48, 12
OPTIONS = ("frame_end=3", "max_num_objects=5", f"resolution={W}x{H}", "events=true",
           "event_subframes=2", "event_refractory_us=0")


@pytest.fixture(scope="module")
def scenes(tmp_path_factory):
    root = tmp_path_factory.mktemp("rig_events")
    stereo = _worker(root / "stereo", 7, *OPTIONS, "cameras=stereo", "baseline=0.4")
    mono = _worker(root / "mono", 7, *OPTIONS)
    return root, stereo, mono


def _log_intensity(rgba):
    from kubric.annotations.event_camera import SensorModel, srgb_to_log_intensity
    return srgb_to_log_intensity(rgba[..., :3].astype(np.float64), SensorModel().eps)


def _matching_fraction(events, log_i, a: int) -> tuple[float, int]:
    """Fraction of pixels where ±threshold summed over the events of frame interval a → a + 1
    is within one threshold of ``log_i``'s change, and how many events that interval has."""
    c_pos, c_neg = events["contrast_thresholds"]
    sel = (events["t"] > round(a / RATE * 1e6)) & (events["t"] <= round((a + 1) / RATE * 1e6))
    x, y, p = events["x"][sel], events["y"][sel], events["p"][sel]
    total = np.zeros(c_pos.shape)
    np.add.at(total, (y, x), np.where(p == 1, c_pos[y, x], -c_neg[y, x]))
    within = np.abs(total - (log_i[a + 1] - log_i[a])) <= np.maximum(c_pos, c_neg)
    return float(within.mean()), int(sel.sum())


def test_right_events_sum_to_the_right_camera_s_frames(scenes):
    from kubric.io.event_h5 import read_events
    _, stereo, _ = scenes
    right = read_events(stereo / "events_right.h5")
    right_log = _log_intensity(_right_layers(stereo)["rgba"])
    left_log = _log_intensity(file_io.read_image_dict(stereo)["rgba"])
    for a in (0, 1):
        fraction, count = _matching_fraction(right, right_log, a)
        assert fraction >= 0.95 and count > 50, (a, fraction, count)
        wrong, _ = _matching_fraction(right, left_log, a)
        assert wrong < fraction - 0.02, (a, wrong, fraction)  # another camera's change


def test_left_events_are_the_mono_scene_s_and_thresholds_differ(scenes):
    from kubric.io.event_h5 import read_events
    _, stereo, mono = scenes
    left, alone = read_events(stereo / "events.h5"), read_events(mono / "events.h5")
    for key in ("x", "y", "t", "p", "contrast_thresholds"):
        assert np.array_equal(left[key], alone[key]), key
    right = read_events(stereo / "events_right.h5")
    assert not np.array_equal(right["contrast_thresholds"], left["contrast_thresholds"])
    assert abs(right["contrast_thresholds"].mean() - left["contrast_thresholds"].mean()) < 0.01
    sensor = json.loads((stereo / "metadata.json").read_text())["metadata"]["event_camera"]
    assert sensor["file"] == "events.h5" and sensor["num_events"] == len(left["t"])
    assert sensor["cameras"] == {"right": {"file": "events_right.h5",
                                           "num_events": len(right["t"])}}


def test_rig_events_pack_per_camera(scenes, tmp_path):
    from kubric.datasets import load, pack
    from kubric.io.event_h5 import read_events
    root, stereo, _ = scenes
    pack(root / "stereo", tmp_path / "ds", splits={"train": 1})
    example = load(tmp_path / "ds", "train")[0]
    right = read_events(stereo / "events_right.h5")
    got = example["cameras"]["right"]["event_stream"]
    for key in ("x", "y", "t", "p", "contrast_thresholds"):
        assert np.array_equal(got[key], right[key]), key
    left = read_events(stereo / "events.h5")
    assert np.array_equal(example["event_stream"]["t"], left["t"])

"""Event streams (kubric.annotations.event_camera, kubric.io.event_h5) from raycast sub-frames,
checked against the log-intensity change of frames rendered separately by the raycast backend."""

import numpy as np
import pytest

import kubric as kb
from kubric.annotations.event_camera import SensorModel, simulate, srgb_to_log_intensity
from kubric.recipes.exposure_options import ExposureOptions

pytest.importorskip("embreex")
pytest.importorskip("h5py")

W, H, RATE = 64, 48, 12


def _scene():
    scene = kb.Scene(resolution=(W, H), frame_start=0, frame_end=4)
    scene.frame_rate = RATE
    scene += kb.Cube(name="floor", scale=(8, 8, 0.1), position=(0, 0, -0.1), static=True,
                     material=kb.FlatMaterial(color=kb.Color(0.3, 0.3, 0.3)))
    scene += kb.DirectionalLight(position=(1, -1, 3), look_at=(0, 0, 0), intensity=2.0)
    ball = kb.Sphere(name="ball", scale=0.6, material=kb.PrincipledBSDFMaterial(
        color=kb.Color(0.9, 0.7, 0.2)))
    box = kb.Cube(name="box", scale=0.4, material=kb.PrincipledBSDFMaterial(
        color=kb.Color(0.1, 0.4, 0.9)))
    scene += ball
    scene += box
    for f in range(5):
        ball.position = (-2.0 + 0.9 * f, 0.3, 0.6)
        box.position = (1.5 - 0.6 * f, -0.8 + 0.2 * f, 0.4)
        ball.keyframe_insert("position", f)
        box.keyframe_insert("position", f)
    scene.camera = kb.PerspectiveCamera(position=(0, -7, 4), look_at=(0, 0, 0.3))
    return scene


def test_events_sum_to_the_log_intensity_change_between_frames(tmp_path):
    from kubric.io.event_h5 import encode_events, read_events
    from kubric.renderer.raycast_subframes import subframe_layers
    scene, k, model = _scene(), 8, SensorModel(refractory_us=50.0)
    frames = [1, 2]
    rgba = subframe_layers(scene, frames, np.arange(k) / k, ("rgba",))["rgba"]
    last = subframe_layers(scene, [3], [0.0], ("rgba",))["rgba"]
    samples = np.concatenate([rgba.reshape(-1, H, W, 4), last.reshape(-1, H, W, 4)])
    times = (np.arange(len(samples)) / k + 1) / RATE * 1e6  # µs, 0 at frame 0
    thresholds = model.thresholds(H, W, np.random.RandomState(7))
    events = simulate(srgb_to_log_intensity(samples[..., :3], model.eps), times, thresholds,
                      model)
    path = tmp_path / "events.h5"
    path.write_bytes(encode_events(events, thresholds, {"contrast_pos": model.contrast_pos}))
    got = read_events(path)
    np.testing.assert_array_equal(got["x"], events["x"])
    assert np.abs(got["t"] - events["t"]).max() <= 0.5
    np.testing.assert_allclose(got["contrast_thresholds"], thresholds, rtol=1e-6)
    # DSEC's lookup table: ms_to_idx[ms] is the first event at t ≥ 1000·ms
    idx, t = got["ms_to_idx"].astype(np.int64), got["t"]
    assert len(idx) == t[-1] // 1000 + 1
    assert all((t[i:] >= 1000 * ms).all() and (t[:i] < 1000 * ms).all()
               for ms, i in list(enumerate(idx))[::37])
    # reference: frames 1, 2, 3 rendered by the backend's own render(), log intensity by hand
    frames_rgb = kb.renderer.create("raycast", scene).render(
        frames=[1, 2, 3], return_layers=("rgba",))["rgba"][..., :3].astype(np.float64) / 255
    linear = np.where(frames_rgb <= 0.04045, frames_rgb / 12.92,
                      ((frames_rgb + 0.055) / 1.055) ** 2.4)
    log_i = np.log(linear @ [0.2126, 0.7152, 0.0722] + model.eps)
    c_pos, c_neg = got["contrast_thresholds"]
    moving = 0
    for a in (0, 1):
        t0, t1 = (a + 1) / RATE * 1e6, (a + 2) / RATE * 1e6
        sel = (got["t"] > round(t0)) & (got["t"] <= round(t1))
        x, y, p = got["x"][sel], got["y"][sel], got["p"][sel]
        total = np.zeros((H, W))
        np.add.at(total, (y, x), np.where(p == 1, c_pos[y, x], -c_neg[y, x]))
        change = log_i[a + 1] - log_i[a]
        within = np.abs(total - change) <= np.maximum(c_pos, c_neg)
        assert within.mean() >= 0.95, within.mean()
        moving += (np.abs(change) > 1.0).sum()
    assert moving > 100  # the objects' motion really makes events
    # the refractory period holds for every pixel
    key = got["y"].astype(np.int64) * W + got["x"]
    order = np.lexsort((got["t"], key))
    same = np.diff(key[order]) == 0
    assert (np.diff(got["t"][order])[same] >= 50 - 1).all()


def test_sensor_model_refuses_bad_values_and_draws_thresholds_from_the_rng():
    with pytest.raises(ValueError, match="contrast_pos must be > 0"):
        SensorModel(contrast_pos=0)
    with pytest.raises(ValueError, match="refractory_us must be ≥ 0"):
        SensorModel(refractory_us=-1)
    model = SensorModel(threshold_spread=0.05)
    a = model.thresholds(8, 8, np.random.RandomState(1))
    np.testing.assert_array_equal(a, model.thresholds(8, 8, np.random.RandomState(1)))
    assert a.shape == (2, 8, 8) and 0.15 < a.mean() < 0.25 and a.std() > 0.02


def test_simulate_fires_one_event_per_threshold_crossing_at_the_crossing_time():
    # one pixel, log intensity 0 → 1 over 1000 µs, C+ = 0.3: crossings at 0.3, 0.6, 0.9
    thresholds = np.full((2, 1, 1), 0.3)
    events = simulate(np.array([0.0, 1.0]).reshape(2, 1, 1), [0.0, 1000.0], thresholds,
                      SensorModel())
    np.testing.assert_allclose(events["t"], [300.0, 600.0, 900.0])
    np.testing.assert_array_equal(events["p"], [1, 1, 1])
    # back down to 0.05: the reference is at 0.9, so OFF at 0.6, 0.3 (not 0.0); a 350 µs
    # refractory period drops the ON at 600 µs and the OFF at 0.3 (316 µs after the one at 0.6)
    events = simulate(np.array([0.0, 1.0, 0.05]).reshape(3, 1, 1), [0.0, 1000.0, 2000.0],
                      thresholds, SensorModel(refractory_us=350.0))
    np.testing.assert_allclose(events["t"], [300.0, 900.0, 1000.0 + 0.4 / 0.95 * 1000.0])
    np.testing.assert_array_equal(events["p"], [1, 1, 0])


def test_noise_events_are_a_poisson_process_per_pixel():
    from kubric.annotations.event_camera import add_noise
    model = SensorModel(noise_rate_hz=50.0)
    empty = {"x": np.zeros(0, np.uint16), "y": np.zeros(0, np.uint16), "t": np.zeros(0),
             "p": np.zeros(0, np.uint8)}
    noisy = add_noise(empty, 40, 50, 0.0, 2e6, model, np.random.RandomState(3))
    n = len(noisy["t"])  # expected 50 Hz × 2 s × 2000 px = 200000, sd ≈ 447
    assert abs(n - 200000) < 5 * 447
    assert (np.diff(noisy["t"]) >= 0).all() and 0.49 < noisy["p"].mean() < 0.51
    per_pixel = np.bincount(noisy["y"].astype(int) * 50 + noisy["x"], minlength=2000)
    assert abs(per_pixel.var() / per_pixel.mean() - 1) < 0.1  # Poisson: variance = mean
    assert add_noise(empty, 4, 4, 0.0, 1e6, SensorModel(), np.random.RandomState(3)) is empty


class Stub(ExposureOptions):
    """The exposure options as a recipe holds them (defaults, then ``values``)."""

    def __init__(self, **values):
        self.values = {name: opt.default for name, opt in vars(ExposureOptions).items()
                       if hasattr(opt, "default") and not name.startswith("_")}
        self.values.update(values)


def _sums_match_frames(out, log_i) -> list:
    """Between frame times 0→1 and 1→2, polarity × threshold summed per pixel is within one
    threshold of the frames' log-intensity change at ≥ 95 % of pixels; returns [(the interval's
    events (mask), a)]."""
    c_pos, c_neg = out["contrast_thresholds"]
    found = []
    for a in (0, 1):
        sel = (out["t"] > round(a / RATE * 1e6)) & (out["t"] <= round((a + 1) / RATE * 1e6))
        x, y, p = out["x"][sel], out["y"][sel], out["p"][sel]
        total = np.zeros((H, W))
        np.add.at(total, (y, x), np.where(p == 1, c_pos[y, x], -c_neg[y, x]))
        within = np.abs(total - (log_i[a + 1] - log_i[a])) <= np.maximum(c_pos, c_neg)
        assert within.mean() >= 0.95 and sel.sum() > 100
        found.append((sel, a))
    return found


def test_recipe_event_files_from_raycast_subframes_keep_frame_times(tmp_path):
    from kubric.io.event_h5 import EVENTS_H5_FILE, read_events

    scene = _scene()
    scene.frame_start, scene.frame_end = 1, 3
    frames_rgba = kb.renderer.create("raycast", scene).render(
        frames=[1, 2, 3], return_layers=("rgba",))["rgba"]
    files = Stub(events=True, event_subframes=4, event_refractory_us=0.0).event_files(
        scene, {"rgba": frames_rgba}, seed=5)
    (tmp_path / EVENTS_H5_FILE).write_bytes(files[EVENTS_H5_FILE])
    out = read_events(tmp_path)
    sensor = scene.metadata["event_camera"]
    assert sensor["source"] == "raycast sub-frames K=4, anchored at the rendered frames"
    assert sensor["num_events"] == len(out["t"])
    # t = 0 at frame_start; the stream spans frames 1 → 3
    assert out["t"].min() >= 0 and out["t"].max() <= round(2 / RATE * 1e6)
    log_i = srgb_to_log_intensity(frames_rgba[..., :3], SensorModel().eps)
    _sums_match_frames(out, log_i)


def test_raycast_subframe_events_sum_to_another_renderer_s_frames(tmp_path):
    """The raycast sub-frames are anchored at the delivered frames: with frames a different
    renderer made (here the raycast frames darkened, tinted and noised, as a path tracer's
    differ from Lambert shading), the events between two frame times still sum to *those*
    frames' log-intensity change, and edges crossing inside the interval still fire there."""
    from kubric.io.event_h5 import EVENTS_H5_FILE, read_events

    scene = _scene()
    scene.frame_start, scene.frame_end = 1, 3
    rgba = kb.renderer.create("raycast", scene).render(
        frames=[1, 2, 3], return_layers=("rgba",))["rgba"].astype(np.float64)
    noise = np.random.RandomState(0).normal(0, 2, rgba.shape[:3] + (3,))
    rgba[..., :3] = np.clip(rgba[..., :3] * [0.6, 0.75, 0.9] + 20 + noise, 0, 255)
    other = rgba.round().astype(np.uint8)
    files = Stub(events=True, event_subframes=4, event_refractory_us=0.0).event_files(
        scene, {"rgba": other}, seed=5)
    (tmp_path / EVENTS_H5_FILE).write_bytes(files[EVENTS_H5_FILE])
    out = read_events(tmp_path)
    log_i = srgb_to_log_intensity(other[..., :3], SensorModel().eps)
    for sel, a in _sums_match_frames(out, log_i):
        phase = (out["t"][sel] - a / RATE * 1e6) / (1e6 / RATE)
        assert ((phase > 0.05) & (phase < 0.7)).sum() > 10
    unanchored = srgb_to_log_intensity(
        kb.renderer.create("raycast", scene).render(frames=[1, 2, 3], return_layers=("rgba",))
        ["rgba"][..., :3], SensorModel().eps)
    with pytest.raises(AssertionError):  # the raycast frames' own change is not what summed
        _sums_match_frames(out, unanchored)



def test_flow_warped_frames_match_a_render_between_them_better_than_blending():
    """kubric.annotations.flow_interpolation: the image warped halfway along the exact flow is
    the raycast render at that half frame (an independent cast at t + ½) up to the shading of
    moving surfaces, and far closer to it than the linear blend of the two frames, on the pixels
    where an object moved; the frames themselves come back at s = 0 and 1."""
    from kubric.annotations.flow_interpolation import interpolate
    from kubric.renderer.raycast_subframes import subframe_layers

    scene = _scene()
    got = subframe_layers(scene, [1, 2], [0.0], ("rgba", "forward_flow", "backward_flow",
                                                 "depth", "segmentation"))
    rgb = got["rgba"][:, 0, ..., :3].astype(np.float64)
    mid = subframe_layers(scene, [1.5], [0.0], ("rgba", "segmentation"))
    args = (rgb[0], rgb[1], got["forward_flow"][0, 0], got["backward_flow"][1, 0],
            got["depth"][0, 0], got["depth"][1, 0])
    assert (interpolate(*args, 0.0) == rgb[0]).all() and (interpolate(*args, 1.0) == rgb[1]).all()
    warped = interpolate(*args, 0.5)
    ref = mid["rgba"][0, 0, ..., :3].astype(np.float64)
    labels = [got["segmentation"][0, 0, ..., 0], got["segmentation"][1, 0, ..., 0],
              mid["segmentation"][0, 0, ..., 0]]
    moved = (labels[0] != labels[2]) | (labels[1] != labels[2])  # an edge passed the pixel
    assert moved.sum() > 50
    err_warp = np.abs(warped - ref).mean(-1)[moved]
    err_blend = np.abs(0.5 * (rgb[0] + rgb[1]) - ref).mean(-1)[moved]
    assert err_warp.mean() < 0.35 * err_blend.mean(), (err_warp.mean(), err_blend.mean())
    assert np.median(err_warp) < 3.0  # 8-bit levels
    with pytest.raises(ValueError, match=r"s must be in \[0, 1\], got 1.5"):
        interpolate(*args, 1.5)


def test_recipe_event_files_from_flow_warped_frames(tmp_path):
    """event_interpolation=flow: K samples per frame warped from the rendered frames; events
    between two frame times still sum to the frames' log-intensity change (one threshold)."""
    from kubric.io.event_h5 import EVENTS_H5_FILE, read_events

    scene = _scene()
    scene.frame_start, scene.frame_end = 1, 3
    layers = kb.renderer.create("raycast", scene).render(
        frames=[1, 2, 3], return_layers=("rgba", "forward_flow", "backward_flow", "depth"))
    files = Stub(events=True, event_subframes=4, event_interpolation="flow",
                 event_refractory_us=0.0).event_files(scene, layers, seed=5)
    (tmp_path / EVENTS_H5_FILE).write_bytes(files[EVENTS_H5_FILE])
    out = read_events(tmp_path)
    assert scene.metadata["event_camera"]["source"] == "flow sub-frames K=4"
    log_i = srgb_to_log_intensity(layers["rgba"][..., :3], SensorModel().eps)
    for sel, a in _sums_match_frames(out, log_i):  # sub-frame events inside each interval
        phase = (out["t"][sel] - a / RATE * 1e6) / (1e6 / RATE)
        assert ((phase > 0.05) & (phase < 0.7)).sum() > 10

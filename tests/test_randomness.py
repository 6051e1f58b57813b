"""Seeded sampling helpers."""

import inspect

import numpy as np
import pytest

import kubric as kb
from kubric import randomness
from kubric.assets import clevr


def test_no_function_has_a_default_rng_object():
    for name, fn in inspect.getmembers(randomness, inspect.isfunction):
        params = inspect.signature(fn).parameters
        if "rng" in params:
            assert params["rng"].default in (None, inspect.Parameter.empty), name


def test_omitted_rng_needs_setup_and_then_uses_the_seeded_worker_rng(tmp_path):
    # random_clevr_color has no upstream counterpart with an unseeded default
    with pytest.raises(TypeError, match=r"needs rng=.*or call kb.setup\(flags\) first"):
        randomness.random_clevr_color()
    parser = kb.ArgumentParser()
    for attempt in range(2):
        flags = parser.parse_args(["--seed", "7", "--job-dir", str(tmp_path / f"out{attempt}")])
        _, rng, _, _ = kb.setup(flags)
        # upstream style: positional axis + rng, and calls without rng at all
        first = (kb.random_rotation([0, 0, 1], rng), kb.random_hue_color(),
                 kb.sample_point_in_half_sphere_shell(7, 9).tolist())
        if attempt == 0:
            expected = first
    assert first == expected  # the seed fixes what rng-less calls return


def test_the_worker_rng_binding_ends_with_its_owner(tmp_path):
    """No reset between tests: once the rng kb.setup returned is dropped, rng=None is no longer
    bound (an error where upstream had no unseeded default) and kb.done has no output directory
    to mark."""
    def upstream_script(job_dir):
        scene, rng, output_dir, _ = kb.setup(kb.ArgumentParser().parse_args(
            ["--seed", "3", "--job-dir", str(job_dir)]))
        sample = kb.random_hue_color()
        assert sample == kb.random_hue_color(rng=np.random.RandomState(3))
        assert randomness.worker_rng() is rng and rng.output_dir == output_dir
        return sample

    upstream_script(tmp_path / "a")
    assert randomness.worker_rng() is None
    with pytest.raises(TypeError, match="keep the rng it returns"):
        randomness.random_clevr_color()
    assert kb.done() is None and not (tmp_path / "a" / "_SUCCESS").exists()
    with pytest.raises(TypeError, match="needs a kubric.randomness.WorkerRandomState"):
        randomness.bind_worker_rng(np.random.RandomState(0))


def test_same_seed_same_samples_and_rng_required():
    a = [kb.random_hue_color(rng=np.random.RandomState(3)) for _ in range(2)]
    assert a[0] == a[1]
    assert kb.random_rotation(rng=np.random.default_rng(1)) == kb.random_rotation(
        rng=np.random.default_rng(1))
    with pytest.raises(TypeError, match="needs rng="):
        kb.random_hue_color(rng=42)


def test_random_rotation_is_unit_and_about_axis():
    rng = np.random.RandomState(0)
    q = np.array([kb.random_rotation(rng=rng) for _ in range(2000)])
    np.testing.assert_allclose(np.linalg.norm(q, axis=1), 1, atol=1e-9)
    # uniform over SO(3): the rotated x axis is uniform on the sphere, mean ≈ 0
    xs = np.array([kb.Quaternion(v).rotate([1, 0, 0]) for v in q])
    assert np.all(np.abs(xs.mean(axis=0)) < 0.05)
    qz = kb.random_rotation(axis="Z", rng=rng)
    assert qz[1] == pytest.approx(0) and qz[2] == pytest.approx(0)


def test_position_sampler_keeps_bounding_box_in_region():
    rng = np.random.RandomState(5)
    region = [[-1, -2, 0], [3, 2, 4]]
    cube = kb.Cube(scale=0.5)
    for _ in range(200):
        kb.rotation_sampler()(cube, rng)
        kb.position_sampler(region)(cube, rng)
        box = cube.aabbox
        assert np.all(box[0] >= np.array(region[0]) - 1e-5)
        assert np.all(box[1] <= np.array(region[1]) + 1e-5)
    with pytest.raises(ValueError, match="does not fit in region"):
        kb.position_sampler([[0, 0, 0], [0.1, 0.1, 0.1]])(cube, rng)


def test_bottom_sampler_rests_on_floor():
    cube = kb.Cube(scale=(1, 1, 0.3))
    kb.bottom_sampler([[-5, -5, 2], [5, 5, 9]])(cube, np.random.RandomState(0))
    assert cube.aabbox[0, 2] == pytest.approx(2.0, abs=1e-5)


def test_resample_while_counts_trials_and_gives_up_clearly():
    rng = np.random.RandomState(0)
    cube = kb.Cube()
    n = kb.resample_while(cube, [kb.position_sampler([[-10] * 3, [10] * 3])],
                          condition=lambda obj: obj.position[0] < 5, max_trials=1000, rng=rng)
    assert n >= 1 and cube.position[0] >= 5
    with pytest.raises(RuntimeError, match="Cube: no valid sample after 3 trials"):
        kb.resample_while(cube, [], condition=lambda obj: True, max_trials=3, rng=rng)


def test_rotations_too_big_for_the_region_are_rejected_trials():
    rng = np.random.RandomState(2)
    big = kb.Cube(scale=1.4)  # 2.8 m cube: fits a 4 m tall region only in some rotations
    region = [[-5, -5, 1], [5, 5, 5]]
    samplers = [kb.rotation_sampler(), kb.position_sampler(region)]
    for _ in range(20):
        kb.resample_while(big, samplers, condition=lambda obj: False, max_trials=500, rng=rng)
        assert big.aabbox[0, 2] >= 1 - 1e-5 and big.aabbox[1, 2] <= 5 + 1e-5
    huge = kb.Cube(scale=3)
    with pytest.raises(RuntimeError, match="after 7 trials; 7 of them did not fit in the region"):
        kb.resample_while(huge, samplers, condition=lambda obj: False, max_trials=7, rng=rng)


def test_half_sphere_shell():
    rng = np.random.RandomState(1)
    pts = np.array([kb.sample_point_in_half_sphere_shell(7, 9, rng=rng) for _ in range(500)])
    r = np.linalg.norm(pts, axis=1)
    assert np.all((r >= 7) & (r <= 9)) and np.all(pts[:, 2] >= 0)


def test_upstream_sample_color_and_sizes():
    rng = np.random.RandomState(0)
    label, color = randomness.sample_color("clevr", rng)
    assert color == clevr.COLORS[label]
    assert randomness.sample_color("uniform_hue", rng)[0] is None
    assert randomness.sample_color("gray", rng) == ("gray", kb.get_color("gray"))
    label, size = randomness.sample_sizes("clevr", rng)
    assert clevr.SIZES[label] == size
    assert 0.7 <= randomness.sample_sizes("uniform", rng)[1] <= 1.4
    assert randomness.sample_sizes("const", rng) == (None, 1.0)
    with pytest.raises(ValueError, match="unknown size strategy 'huge'; allowed: clevr"):
        randomness.sample_sizes("huge", rng)


def test_clevr_palette_values():
    assert clevr.COLORS_RGB255["yellow"] == (255, 238, 5)
    assert clevr.SIZES == {"small": 0.7, "large": 1.4}
    name, color = randomness.random_clevr_color(rng=np.random.RandomState(0))
    assert color == clevr.COLORS[name]

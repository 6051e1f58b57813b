"""The hello-world example runs end to end (tiny resolution) and writes readable outputs."""

import runpy
from pathlib import Path

import numpy as np
import pytest

import kubric as kb

EXAMPLE = Path(__file__).resolve().parent.parent / "examples" / "helloworld.py"


@pytest.mark.blender
def test_helloworld_example(tmp_path):
    main = runpy.run_path(str(EXAMPLE))["main"]
    frame = main(["--output", str(tmp_path), "--resolution", "32", "--samples", "2"])
    for name in ("helloworld.blend", "helloworld.png", "helloworld_segmentation.png",
                 "helloworld_depth.png"):
        assert (tmp_path / name).is_file(), name
    rgba = kb.read_png(tmp_path / "helloworld.png")
    assert rgba.shape == (32, 32, 4) and rgba[..., :3].mean() > 20
    seg = kb.read_palette_png(tmp_path / "helloworld_segmentation.png")
    assert set(np.unique(seg)) <= {0, 1, 2} and {1, 2} <= set(np.unique(seg))
    assert frame["depth"].shape == (32, 32, 1)
    ball = frame["segmentation"][..., 0] == 2
    # the camera is √19 ≈ 4.359 m from the ball's centre (radius 1): nearest surface 3.359 m
    assert 3.355 < frame["depth"][ball].min() < 3.45


FIGURE3 = EXAMPLE.parent / "figure3.py"


@pytest.mark.blender  # main() builds its Blender renderer before placing objects
def test_figure3_printed_region_cannot_hold_kubasic_shapes(tmp_path):
    """The printed listing's spawn region is 2 × 2 × 1 m above the floor: eight unit-sized KuBasic
    shapes do not fit, and placement must stop with the clear error rather than overlap or hang."""
    main = runpy.run_path(str(FIGURE3))["main"]
    with pytest.raises(RuntimeError, match=r"no valid sample after 100 trials; \d+ of them did "
                                           r"not fit in the region"):
        main(["--output", str(tmp_path), "--resolution", "16", "--frames", "2",
              "--spawn-region", "-1", "-1", "0", "1", "1", "1"])
    assert not (tmp_path / "metadata.json").exists()


@pytest.mark.blender
def test_figure3_listing_runs_at_its_default_region(tmp_path):
    """examples/figure3.py with its documented defaults (only size knobs made small)."""
    main = runpy.run_path(str(FIGURE3))["main"]
    out = main(["--output", str(tmp_path), "--resolution", "32", "--frames", "3",
                "--samples", "2"])
    assert (out / "scene.blend").stat().st_size > 100_000
    meta = kb.read_json(out / "metadata.json")
    kubasic_ids = {"cone", "cube", "cylinder", "gear", "sphere", "sponge", "spot", "suzanne",
                   "teapot", "torus", "torus_knot"}
    instances = [i for i in meta["instances"] if i["asset_id"] in kubasic_ids]
    assert len(instances) == 8 and len(meta["instances"]) == 9  # + the floor
    for inst in instances:  # simulated: 3 frames of positions, all above the floor's top
        positions = np.asarray(inst["positions"])
        assert positions.shape == (3, 3) and (positions[:, 2] > 0).all()
    seg = np.stack([kb.read_palette_png(out / f"segmentation_{i:05d}.png") for i in range(3)])
    assert len(set(np.unique(seg)) - {0}) >= 4  # several objects visible at 32²
    depth = kb.read_tiff(out / "depth_00000.tiff")
    # camera at (0, 5, 5) looking 45° down with a 39.6° field of view: the 20 × 20 m floor fills
    # the frame, its farthest visible point is 5 / sin(25.2°) ≈ 11.7 m away
    assert depth.shape == (32, 32, 1) and 0.5 < depth.min() and depth.max() < 12.5

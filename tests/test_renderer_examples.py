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

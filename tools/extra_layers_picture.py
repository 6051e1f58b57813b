"""Draw one frame of a scene's opt-in layers side by side, as ``kubric view`` draws them (the
picture of docs/conventions.md#opt-in-ground-truth-from-the-scene-model).

Usage::

    kubric worker movi_a --seed 7 --out out/ --set resolution=128 --set frame_end=2 \\
        --set renderer=raycast --set min_num_objects=7 --set max_num_objects=8 \\
        --set extra_layers=amodal,scene_flow,occlusion_boundaries,material_ids,part_ids
    python tools/extra_layers_picture.py out/scene_00000007 docs/img/extra_layers.png [--frame 1]

Panels: RGB, visible segmentation, amodal segmentation (how many instances cover each pixel),
occlusion boundaries (white: occluding side, grey: occluded side), forward scene flow (length),
material ids.
"""

from __future__ import annotations

import argparse

import numpy as np

from kubric.annotations.pictures import layer_pictures
from kubric.io.layers import read_image_dict
from kubric.io.png_io import encode_png

PANELS = ("rgba", "segmentation", "amodal_segmentation", "occlusion_boundaries",
          "forward_scene_flow", "material_ids")


def write_row(panels, out, gap: int = 2) -> None:
    """Write (H, W_i, 3) uint8 pictures side by side, ``gap`` white pixels apart, as a PNG."""
    white = np.full((panels[0].shape[0], gap, 3), 255, np.uint8)
    row = np.concatenate([part for p in panels for part in (p, white)][:-1], axis=1)
    with open(out, "wb") as f:
        f.write(encode_png(np.ascontiguousarray(row)))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scene")
    ap.add_argument("out")
    ap.add_argument("--frame", type=int, default=1)
    args = ap.parse_args()
    layers = read_image_dict(args.scene, PANELS)
    panels = [layer_pictures(name, layers[name])[args.frame] for name in PANELS]
    write_row(panels, args.out)


if __name__ == "__main__":
    main()

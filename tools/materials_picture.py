"""Put frame ``--frame`` of two scenes side by side: the picture of docs/materials.md (a MOVi-C
scene with its own materials beside the same seed with ``material_source=procedural``).

Usage::

    for m in none procedural; do
      kubric worker movi_c --seed 7 --out out_$m/ --set resolution=128 --set frame_end=1 \\
          --set samples=16 --set material_source=$m
    done
    python tools/materials_picture.py out_none/scene_00000007 out_procedural/scene_00000007 \\
        docs/img/materials_movi_c.png
"""

from __future__ import annotations

import argparse

import numpy as np

from kubric.io.layers import read_image_dict
from kubric.io.png_io import encode_png


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("left")
    ap.add_argument("right")
    ap.add_argument("out")
    ap.add_argument("--frame", type=int, default=0, help="index into the rendered frames")
    args = ap.parse_args()
    images = [read_image_dict(scene, ("rgba",))["rgba"][args.frame, ..., :3]
              for scene in (args.left, args.right)]
    gap = np.full((images[0].shape[0], 4, 3), 255, np.uint8)
    with open(args.out, "wb") as f:
        f.write(encode_png(np.concatenate([images[0], gap, images[1]], axis=1)))


if __name__ == "__main__":
    main()

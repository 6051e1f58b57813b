"""Put frame F of the RGB of several scenes side by side (the pictures comparing sources in
docs/assets.md).

Usage::

    python tools/side_by_side.py OUT.png SCENE_DIR [SCENE_DIR ...] [--frame 0]
"""

from __future__ import annotations

import argparse

import numpy as np

from kubric.io.layers import read_image_dict
from kubric.io.png_io import encode_png


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out")
    ap.add_argument("scenes", nargs="+")
    ap.add_argument("--frame", type=int, default=0)
    args = ap.parse_args()
    panels = [read_image_dict(s, ("rgba",))["rgba"][args.frame][..., :3] for s in args.scenes]
    gap = np.full((panels[0].shape[0], 4, 3), 255, np.uint8)
    row = np.concatenate([part for p in panels for part in (p, gap)][:-1], axis=1)
    with open(args.out, "wb") as f:
        f.write(encode_png(np.ascontiguousarray(row)))


if __name__ == "__main__":
    main()

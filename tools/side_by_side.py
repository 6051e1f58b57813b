"""Put frame F of the RGB of several scenes side by side (the pictures comparing sources in
docs/assets.md).

Usage::

    python tools/side_by_side.py OUT.png SCENE_DIR [SCENE_DIR ...] [--frame 0]
"""

from __future__ import annotations

import argparse

from extra_layers_picture import write_row

from kubric.io.layers import read_image_dict


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out")
    ap.add_argument("scenes", nargs="+")
    ap.add_argument("--frame", type=int, default=0)
    args = ap.parse_args()
    panels = [read_image_dict(s, ("rgba",))["rgba"][args.frame][..., :3] for s in args.scenes]
    write_row(panels, args.out, gap=4)


if __name__ == "__main__":
    main()

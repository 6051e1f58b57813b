"""Hello world: a floor, a ball, a sun and a camera → .blend, RGBA, segmentation and depth.

Run: ``python examples/helloworld.py [--output output] [--resolution 256] [--samples 64]``.
Writes ``helloworld.blend`` (open it in Blender), ``helloworld.png`` (RGBA),
``helloworld_segmentation.png`` (palette labels: 1 = floor, 2 = ball) and
``helloworld_depth.png`` (16-bit, scaled over the depth range, printed).
"""

from __future__ import annotations

import argparse
import logging
from pathlib import Path

import kubric as kb


def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--output", default="output", help="output directory")
    parser.add_argument("--resolution", type=int, default=256, help="width = height (px)")
    parser.add_argument("--samples", type=int, default=64, help="Cycles samples per pixel")
    args = parser.parse_args(argv)
    out = Path(args.output)

    scene = kb.Scene(resolution=(args.resolution, args.resolution))
    renderer = kb.renderer.Blender(scene, samples_per_pixel=args.samples)
    scene += kb.Cube(name="floor", scale=(10, 10, 0.1), position=(0, 0, -0.1))
    scene += kb.Sphere(name="ball", scale=1, position=(0, 0, 1.0))
    scene += kb.DirectionalLight(name="sun", position=(-1, -0.5, 3), look_at=(0, 0, 0),
                                 intensity=1.5)
    scene += kb.PerspectiveCamera(name="camera", position=(3, -1, 4), look_at=(0, 0, 1))

    renderer.save_state(out / "helloworld.blend")
    frame = renderer.render_still()
    kb.write_png(frame["rgba"], out / "helloworld.png")
    kb.write_palette_png(frame["segmentation"], out / "helloworld_segmentation.png")
    depth_range = kb.write_scaled_png(frame["depth"], out / "helloworld_depth.png")
    logging.info("depth range: %s", depth_range)
    print(f"wrote {out}/helloworld.{{blend,png}}, segmentation and depth "
          f"(depth range {depth_range['min']:.3f}..{depth_range['max']:.3f} m)")
    return frame


if __name__ == "__main__":
    main()

"""What floor shadows cost: a MOVi-C-like HDRI scene rendered with the dome's floor unlit
(baseline, measured in the same run) and as a shadow catcher (``FlatMaterial.catch_shadows``).

Scene: the KuBasic dome showing the bpy wheel's ``city.exr`` ground-projected 2 m above the
centre, the same HDRI as world light, 10 cubes and spheres resting on the floor, camera at 8 m
(MOVi's shell), 35 mm lens. Renders alternate between the two settings; each setting's time is the
smaller of ``--repeats`` runs. Also prints the floor's mean colour far from the objects in both
renders (it should agree: the catcher normalises its albedo by the HDRI's irradiance).

Run: ``python benchmarks/bench_shadows.py [--size 256] [--samples 64] [--repeats 2]``.
"""

from __future__ import annotations

import argparse
import json
import resource
import sys
from pathlib import Path

import numpy as np
import smoke_mode
from scipy import ndimage

import kubric as kb

HDRI = (Path(sys.prefix) / "lib/python3.11/site-packages/bpy/5.0/datafiles/studiolights/world"
        / "city.exr")


def cpu_seconds() -> float:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def build(catch: bool, size: int, samples: int):
    from kubric.asset_tools import ensure_kubasic
    from kubric.renderer.blender import Blender

    rng = np.random.RandomState(0)
    scene = kb.Scene(resolution=(size, size), frame_start=1, frame_end=1)
    hdri = kb.Texture(filename=str(HDRI), mapping="environment")
    scene.ambient_illumination = hdri
    scene.background = hdri
    ground = kb.Texture(filename=str(HDRI), mapping="environment", projection_height=2.0)
    dome = ensure_kubasic().create("dome", name="dome", static=True, background=True)
    dome.material = kb.FlatMaterial(color=ground, indirect_visibility=False, catch_shadows=catch)
    scene += dome
    scene += kb.PerspectiveCamera(position=(6, -5, 2.5), look_at=(0, 0, 0.5), focal_length=35,
                                  sensor_width=32)
    for k in range(10):
        cls = kb.Cube if k % 2 else kb.Sphere
        s = float(rng.uniform(0.3, 0.6))
        scene += cls(scale=s, position=(*rng.uniform(-3, 3, 2), s),
                     material=kb.PrincipledBSDFMaterial(color=kb.Color(*rng.uniform(0.1, 0.9, 3)),
                                                        roughness=0.6))
    return scene, Blender(scene, samples_per_pixel=samples, use_denoising=False)


def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=int, default=smoke_mode.size(256, 32))
    parser.add_argument("--samples", type=int, default=smoke_mode.size(64, 1))
    parser.add_argument("--repeats", type=int, default=smoke_mode.size(2, 1))
    args = parser.parse_args(argv)
    times = {"unlit": [], "catch_shadows": []}
    floor = {}
    for _ in range(args.repeats):
        for name in times:
            scene, renderer = build(name == "catch_shadows", args.size, args.samples)
            c0 = cpu_seconds()
            layers = renderer.render(return_layers=("rgba", "segmentation"))
            times[name].append(cpu_seconds() - c0)
            seg = layers["segmentation"][0, ..., 0]
            dome_label = [a.name for a in scene.assets].index("dome") + 1
            far = (seg == dome_label) & ~ndimage.binary_dilation(seg > dome_label, iterations=8)
            rgb = layers["rgba"][0, ..., :3].astype(np.float64)
            floor[name] = [round(float(v), 1) for v in rgb[far].mean(axis=0)]
    best = {k: round(min(v), 2) for k, v in times.items()}
    result = {"size": args.size, "samples": args.samples, "cpu_s_per_frame": best,
              "ratio_catch_over_unlit": round(best["catch_shadows"] / best["unlit"], 2),
              "floor_far_from_objects_rgb_0_255": floor}
    print(json.dumps(result))
    return result


if __name__ == "__main__":
    main()

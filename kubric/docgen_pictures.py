"""``python -m kubric.docgen_pictures``: one small picture per built-in recipe for
``docs/recipes.md`` (``docs/img/recipes/NAME.png``), like the README's picture from
``python -m kubric.demo --figure``.

Each recipe renders one tiny scene (seed :data:`SEED`, :data:`PICTURE_OPTIONS`: 64 px, the
``fast`` quality, the fewest frames or views the recipe allows) with ``kubric worker``; its first
RGB frame, composited over black, is enlarged :data:`ZOOM` × without smoothing and written as the
recipe's picture. Then ``docs/recipes.md`` is regenerated (it shows the pictures that exist). The
whole set took 269 s wall and 90 CPU-s on the loaded, shared 2-core machine (2026-11-26; MOVi-C
84 s of it, converting 50 pybullet_data objects on first use), 176 s wall and 66 CPU-s again with
that collection cached; ``--only NAME[,NAME]`` renders
some (``make docs-pictures`` all).
"""

from __future__ import annotations

import argparse
import pathlib
import subprocess
import sys
import tempfile
import time

import numpy as np

from kubric.annotations.pictures import layer_pictures
from kubric.io.layers import read_frame
from kubric.io.paths import atomic_write_bytes
from kubric.io.png_io import encode_png
from kubric.io.scene_dir import scene_name
from kubric.pipeline.recipe import load_builtin

#: the seed of every recipe's picture
SEED = 0
#: on-screen enlargement of the rendered pixels (nearest neighbour)
ZOOM = 2
_FAST = ["quality=fast"]
_MOVI = _FAST + ["resolution=64", "frame_end=1"]
_VIEWS = _FAST + ["resolution=64x48", "num_views=3", "split_ratio=1,1,1"]
#: categories given to KuBasic's shapes for ``toybox`` (it needs a categorised object source)
TOY_CATEGORIES = {"cube": "boxy", "sponge": "boxy", "sphere": "round", "cylinder": "round",
                  "torus": "round", "teapot": "kitchen"}
#: recipe → the option assignments of its picture's scene
PICTURE_OPTIONS = {
    "bench": ["resolution=64"],
    "movi_a": _MOVI, "movi_b": _MOVI, "movi_c": _MOVI + ["collection_limit=50"],
    "movi_d": _MOVI + ["collection_limit=50"], "movi_e": _MOVI + ["collection_limit=50"],
    "movi_f": _MOVI + ["collection_limit=50"],
    "pose_estimation": _MOVI + ["max_num_people=1", "character_source=procedural",
                                "motion_source=procedural"],
    "complex_brdf": _VIEWS, "klevr": _VIEWS, "toybox": _VIEWS, "nvs": _VIEWS,
    "multiview_matting": _VIEWS, "robust_nerf": _VIEWS, "svr": _VIEWS,
    "texture_nerf": _VIEWS + ["texture_size=64", "band_range=-1,1.2"],
    "vbr": _FAST + ["resolution=64", "num_frames=2"],
}


def picture_path(docs: pathlib.Path, name: str) -> pathlib.Path:
    from kubric.docgen import RECIPE_PICTURE
    return docs / RECIPE_PICTURE.format(name=name)


def scene_picture(scene: pathlib.Path) -> np.ndarray:
    """(ZOOM·H, ZOOM·W, 3) uint8: the scene's first RGB frame over black, enlarged."""
    rgb = layer_pictures("rgba", read_frame(scene, "rgba", 0)[None])[0]
    return np.repeat(np.repeat(rgb, ZOOM, axis=0), ZOOM, axis=1)


def picture_options(name: str, work: pathlib.Path) -> list[str]:
    """The option assignments of ``name``'s picture scene (``toybox``: plus a categorised copy
    of KuBasic written in ``work``)."""
    options = list(PICTURE_OPTIONS[name])
    if name == "toybox":
        from kubric import asset_tools
        from kubric.recipes.klevr import with_categories
        toys = with_categories(asset_tools.ensure_kubasic(), TOY_CATEGORIES, work / "toys")
        options.append(f"objects={toys}")
    return options


def render_picture(name: str, docs: pathlib.Path, work: pathlib.Path) -> pathlib.Path:
    """Render ``name``'s picture scene in ``work`` and write its picture under ``docs``."""
    options = picture_options(name, work)
    cmd = [sys.executable, "-m", "kubric", "worker", name, "--seed", str(SEED),
           "--out", str(work / name)]
    for option in options:
        cmd += ["--set", option]
    done = subprocess.run(cmd, capture_output=True, text=True)
    if done.returncode != 0:
        tail = " ".join(done.stderr.strip().splitlines()[-1:]) or f"exit {done.returncode}"
        raise RuntimeError(f"{name}: kubric worker failed: {tail}")
    path = picture_path(docs, name)
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_bytes(encode_png(scene_picture(work / name / scene_name(SEED))), path)
    return path


def main(argv=None) -> int:
    from kubric.docgen import docs_dir, write_pages
    parser = argparse.ArgumentParser(prog="python -m kubric.docgen_pictures",
                                     description="Render one small picture per built-in recipe "
                                     "for docs/recipes.md, then regenerate the page.")
    parser.add_argument("--only", default=None, help="comma-separated recipe names "
                        "(default: every built-in recipe)")
    parser.add_argument("--docs", type=pathlib.Path, default=None,
                        help="docs folder (default: the repository's docs/)")
    args = parser.parse_args(argv)
    known = sorted(load_builtin())
    names = args.only.split(",") if args.only else known
    unknown = [n for n in names if n not in PICTURE_OPTIONS]
    if unknown:
        print(f"docgen_pictures: error: unknown recipe(s) {', '.join(unknown)}; allowed: "
              f"{', '.join(known)}", file=sys.stderr)
        return 2
    docs = args.docs or docs_dir()
    failed = []
    with tempfile.TemporaryDirectory(prefix="kubric_pictures_") as tmp:
        for name in names:
            start = time.perf_counter()
            try:
                path = render_picture(name, docs, pathlib.Path(tmp))
            except RuntimeError as err:
                failed.append(name)
                print(f"docgen_pictures: {err}", file=sys.stderr)
                continue
            print(f"{path} ({time.perf_counter() - start:.1f} s)", flush=True)
    if args.docs is None:
        write_pages()
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())

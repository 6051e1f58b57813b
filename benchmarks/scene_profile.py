"""Profile one MOVi scene by stage, in this process (run by bench_scene_cost.py in a fresh process).

Usage: ``python benchmarks/scene_profile.py RECIPE SEED OUT_DIR PROFILE_JSON [KEY=VALUE ...]``

Writes the scene like ``kubric worker`` (through :func:`kubric.pipeline.worker.run_scene`) and
PROFILE_JSON: CPU seconds (process-wide, every thread) and wall seconds per stage, measured by
wrapping the pipeline's own functions (with the resident and peak memory after each stage), and
the process's peak RSS. With ``--reference FRAMES`` (e.g. ``1-4``)
nothing is written but ``OUT_DIR/reference.npy``: those frames' RGBA rendered with the given
options (used for the 1024-spp reference).
"""

from __future__ import annotations

import functools
import json
import pathlib
import resource
import sys
import time

_T0 = (time.process_time(), time.perf_counter())
STAGES: dict[str, list[float]] = {}


def _cpu_wall():
    return time.process_time(), time.perf_counter()


def _status_mb(field):
    """VmRSS / VmHWM of this process in MB (Linux /proc)."""
    for line in open("/proc/self/status"):
        if line.startswith(field + ":"):
            return int(line.split()[1]) / 1024
    return float("nan")


def _add(stage, c0, w0):
    c1, w1 = _cpu_wall()
    acc = STAGES.setdefault(stage, [0.0, 0.0, 0.0, 0.0])
    acc[0] += c1 - c0
    acc[1] += w1 - w0
    acc[2] = _status_mb("VmRSS")  # resident after the stage
    acc[3] = _status_mb("VmHWM")  # peak so far


def wrap(owner, name, stage):
    """Replace ``owner.name`` by a version that adds its CPU and wall time to ``stage``."""
    fn = getattr(owner, name)

    @functools.wraps(fn)
    def timed(*args, **kwargs):
        c0, w0 = _cpu_wall()
        try:
            return fn(*args, **kwargs)
        finally:
            _add(stage(*args, **kwargs) if callable(stage) else stage, c0, w0)

    setattr(owner, name, timed)


def install():
    """Wrap the stages of a MOVi scene (imports done here count as start-up)."""
    # ``write_outputs`` writes the files too: recipes import write_scene by name, so it is
    # timed within that stage, not on its own.
    c0, w0 = _T0

    import kubric as kb
    from kubric.recipes import movi_base
    from kubric.renderer import blender, blender_passes
    _add("start-up (python, kubric, bpy import)", c0, w0)

    wrap(movi_base.MoviBase, "open_sources", "asset sources (open / extract)")
    wrap(movi_base.MoviBase, "populate", "scene build + placement")
    wrap(kb.simulator.PyBullet, "run", "simulation")
    wrap(blender.Blender, "__init__", "Blender reset + scene link")
    wrap(blender.Blender, "_render_runs",
         lambda self, frames, prefix, suffix: ("RGB path tracing (+ denoise)" if suffix == ".png"
                                               else "annotation render (EXR)"))
    wrap(blender, "_read_png_rgba", "PNG read-back")
    wrap(blender_passes, "read_multilayer_exr", "EXR read-back")
    wrap(blender_passes, "decode", "EXR decode to layers")
    wrap(movi_base.MoviBase, "write_outputs", "annotations + metadata + writing files")


def reference(recipe, seed, frames, out_dir):
    """Render ``frames`` of scene ``seed`` (RGB only) with the recipe's options → reference.npy."""
    import numpy as np

    from kubric.renderer import blender
    original = blender.Blender.render

    def rgb_only(self, frames_=None, return_layers=None, ignore_missing_textures=False):
        out = original(self, frames, ("rgba",), ignore_missing_textures)
        np.save(out_dir / "reference.npy", out["rgba"])
        raise _Done

    blender.Blender.render = rgb_only
    try:
        recipe.generate(seed, out_dir)
    except _Done:
        pass


class _Done(Exception):
    pass


def main(argv) -> int:
    ref = None
    if argv and argv[0] == "--reference":
        ref, argv = argv[1], argv[2:]
    recipe_name, seed, out_dir, profile_path, *assignments = argv
    install()
    from kubric.pipeline.recipe import get_recipe
    from kubric.pipeline.worker import run_scene
    recipe = get_recipe(recipe_name).from_assignments(assignments)
    out_dir = pathlib.Path(out_dir)
    c0, w0 = _cpu_wall()
    if ref:
        a, b = (int(x) for x in ref.split("-"))
        out_dir.mkdir(parents=True, exist_ok=True)
        reference(recipe, int(seed), list(range(a, b + 1)), out_dir)
    else:
        run_scene(recipe, int(seed), out_dir)
    _add("whole scene (after start-up)", c0, w0)
    usage = resource.getrusage(resource.RUSAGE_SELF)
    pathlib.Path(profile_path).write_text(json.dumps({
        "stages": STAGES, "peak_rss_mb": usage.ru_maxrss / 1024,
        "cpu_total": usage.ru_utime + usage.ru_stime}, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))

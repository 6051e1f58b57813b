"""Profile one MOVi scene by stage, in this process (run by bench_scene_cost.py in a fresh process).

Usage: ``python benchmarks/scene_profile.py RECIPE SEED OUT_DIR PROFILE_JSON [KEY=VALUE ...]``

Writes the scene like ``kubric worker`` (through :func:`kubric.pipeline.worker.run_scene`) and
PROFILE_JSON: CPU seconds (process-wide, every thread) and wall seconds per stage, measured by
wrapping the pipeline's own functions, plus the RGB render's CPU time per frame (Blender's
render_pre / render_post handlers) and the peak RSS. With ``--reference FRAMES`` (e.g. ``1-4``)
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
FRAMES: list[float] = []


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
    """Replace ``owner.name`` by a version that adds its CPU and wall time to ``stage``; a stage
    nested in another is subtracted from the outer one by the report (``inner`` markers)."""
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
    c0, w0 = _T0
    import bpy

    import kubric as kb
    from kubric.io import scene_writer
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
    wrap(scene_writer, "write_scene", "encode + write files")
    wrap(movi_base.MoviBase, "write_outputs", "annotations + metadata (outer)")

    def pre(*_):
        FRAMES.append(time.process_time())

    def post(*_):
        FRAMES[-1] = time.process_time() - FRAMES[-1]

    bpy.app.handlers.render_pre.append(pre)
    bpy.app.handlers.render_post.append(post)
    return kb


def reference(recipe, seed, frames, out_dir):
    """Render ``frames`` of scene ``seed`` (RGB only) with the recipe's options → reference.npy."""
    import numpy as np

    import kubric as kb
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
    assert kb  # imported for the recipe's registry


class _Done(Exception):
    pass


def main(argv) -> int:
    ref = None
    if argv and argv[0] == "--reference":
        ref, argv = argv[1], argv[2:]
    recipe_name, seed, out_dir, profile_path, *assignments = argv
    kb = install()
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
    inner = ("encode + write files",)
    outer = STAGES.get("annotations + metadata (outer)")
    if outer:
        for name in inner:
            if name in STAGES:
                outer[0] -= STAGES[name][0]
                outer[1] -= STAGES[name][1]
        STAGES["annotations + metadata"] = STAGES.pop("annotations + metadata (outer)")
    usage = resource.getrusage(resource.RUSAGE_SELF)
    pathlib.Path(profile_path).write_text(json.dumps({
        "stages": STAGES, "rgb_frame_cpu": FRAMES, "peak_rss_mb": usage.ru_maxrss / 1024,
        "cpu_total": usage.ru_utime + usage.ru_stime}, indent=1))
    assert kb
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))

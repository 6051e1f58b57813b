"""How long a run will take, said before it starts: measured per-recipe render costs scaled by
resolution, frames (or views) and quality, divided over the cores.

Source of the numbers (:data:`RGB_CPU_PER_FRAME`): ``benchmarks/bench_quality_calibration.py``,
2026-11-24, on the project's 2-core machine — the CPU-s of one frame's (or view's) RGB render at
the recipe's own resolution, mean over seeds 1–3, for the settings behind ``quality=draft``,
``fast``, ``default`` (the recipe's calibrated setting) and ``final``
(``docs/data/render-calibration.json``, tabled in docs/render-cost.md; a test checks this table
against that file). Everything else a scene costs — Python, kubric and bpy start-up, physics, the
exact-layer render, read-back and writing files — is :data:`START_CPU` plus :data:`OTHER_CPU_PER_FRAME`
per frame at 256² (``benchmarks/bench_scene_cost.py``'s MOVi-A profile: about 3 CPU-s for 24
frames). Render cost is taken as proportional to pixels and frames; ``samples=N`` scales the
``final`` (64 spp) cost by N / 64. The estimate assumes nothing else runs on the machine; it is a
guide (measured spread across seeds: about ±20 %), not a promise.
"""

from __future__ import annotations

#: recipe → ((width, height) measured at, {quality: CPU-s per frame of the RGB render})
RGB_CPU_PER_FRAME: dict[str, tuple[tuple[int, int], dict[str, float]]] = {
    "complex_brdf": ((128, 128), {"draft": 0.1, "fast": 0.07, "default": 0.4, "final": 0.4}),
    "klevr": ((128, 128), {"draft": 0.22, "fast": 0.27, "default": 1.44, "final": 1.85}),
    "movi_a": ((256, 256), {"draft": 0.54, "fast": 0.88, "default": 5.07, "final": 6.44}),
    "movi_b": ((256, 256), {"draft": 0.63, "fast": 0.99, "default": 5.62, "final": 7.28}),
    "movi_c": ((256, 256), {"draft": 0.76, "fast": 1.26, "default": 7.04, "final": 9.31}),
    "movi_d": ((256, 256), {"draft": 0.84, "fast": 1.38, "default": 7.9, "final": 10.46}),
    "movi_e": ((256, 256), {"draft": 0.73, "fast": 1.22, "default": 6.32, "final": 8.2}),
    "movi_f": ((512, 512), {"draft": 2.92, "fast": 5.16, "default": 29.34, "final": 38.79}),
    "multiview_matting": ((256, 256), {"draft": 0.31, "fast": 0.39, "default": 2.33,
                                       "final": 2.75}),
    "nvs": ((128, 128), {"draft": 0.13, "fast": 0.12, "default": 0.72, "final": 0.81}),
    "pose_estimation": ((256, 256), {"draft": 0.8, "fast": 1.46, "default": 8.43,
                                     "final": 11.22}),
    "robust_nerf": ((128, 128), {"draft": 0.2, "fast": 0.25, "default": 1.34, "final": 1.71}),
    "svr": ((128, 128), {"draft": 0.11, "fast": 0.08, "default": 0.42, "final": 0.49}),
    "texture_nerf": ((128, 128), {"draft": 0.21, "fast": 0.25, "default": 1.73, "final": 1.73}),
    "toybox": ((128, 128), {"draft": 0.17, "fast": 0.15, "default": 0.92, "final": 1.0}),
    "vbr": ((256, 256), {"draft": 0.23, "fast": 0.27, "default": 1.84, "final": 1.84}),
}
#: CPU-s of a worker's start-up (Python, kubric, bpy) and of the rest per frame at 256²
START_CPU = 0.5
OTHER_CPU_PER_FRAME = 0.1
#: a run estimated above this many seconds at a quality other than fast/draft suggests fast
SUGGEST_FAST_ABOVE_S = 60.0
SOURCE = "measured on 2 cores, docs/render-cost.md"


def frames_of(values: dict) -> int | None:
    """Frames (or views) one scene renders, from a recipe's option values; None when unknown."""
    if "num_views" in values:
        return int(values["num_views"])
    if "num_frames" in values:
        return int(values["num_frames"])
    if "frame_end" in values and "frame_start" in values:
        return int(values["frame_end"]) - int(values["frame_start"]) + 1
    return None


def scene_cpu(recipe: str, values: dict, quality: str | None = None) -> float | None:
    """Estimated CPU-s of one scene of ``recipe`` with option ``values`` (``quality`` replaces
    theirs); None for a recipe, renderer or option set the table does not cover."""
    if recipe not in RGB_CPU_PER_FRAME or values.get("renderer", "blender") != "blender":
        return None
    frames = frames_of(values)
    resolution = values.get("resolution")
    if frames is None or resolution is None:
        return None
    (w0, h0), costs = RGB_CPU_PER_FRAME[recipe]
    pixels = resolution[0] * resolution[1]
    quality = quality or values.get("quality", "default")
    if quality not in costs:
        return None
    per_frame = costs[quality]
    if values.get("samples") and quality == values.get("quality", "default"):
        per_frame = costs["final"] * int(values["samples"]) / 64
    render = per_frame * pixels / (w0 * h0) * frames
    return START_CPU + render + OTHER_CPU_PER_FRAME * frames * pixels / 256**2


def _duration(seconds: float) -> str:
    if seconds < 90:
        return f"{max(1, round(seconds))} s"
    if seconds < 5400:
        return f"{round(seconds / 60)} min"
    return f"{seconds / 3600:.1f} h"


def estimate_line(recipe: str, values: dict, scenes: int, cores: int) -> str | None:
    """One line for ``scenes`` scenes on ``cores`` cores (every scene uses all of them), with
    the ``quality=fast`` alternative when this run is long and not already cheap; None when the
    table does not cover the run."""
    cpu = scene_cpu(recipe, values)
    if cpu is None or scenes < 1:
        return None
    cores = max(1, cores)
    wall = cpu * scenes / cores
    quality = values.get("quality", "default")
    setting = f"samples={values['samples']}" if values.get("samples") else f"quality={quality}"
    line = (f"estimate: ~{_duration(wall)} for {scenes} {recipe} scene{'s' * (scenes != 1)} "
            f"({cpu:.0f} CPU-s each at {values['resolution'][0]}x{values['resolution'][1]}, "
            f"{frames_of(values)} frames, {setting}; {cores} cores; {SOURCE})")
    if quality not in ("fast", "draft") and not values.get("samples") \
            and wall > SUGGEST_FAST_ABOVE_S:
        fast = scene_cpu(recipe, values, "fast")
        line += (f"; to explore, --set quality=fast: ~{_duration(fast * scenes / cores)} "
                 f"({cpu / fast:.1f}x cheaper)")
    return line


__all__ = ["RGB_CPU_PER_FRAME", "estimate_line", "frames_of", "scene_cpu"]

"""Event-stream fidelity against cost: where the sub-frame intensity comes from.

One simulated MOVi-A scene (raycast backend: RGB, exact flow and depth; no bpy). The reference
is the event stream of K_REF raycast sub-frames per frame. Each source of intensity is run
through the same sensor (one set of per-pixel thresholds, no refractory period, no noise):

* ``frames``: the rendered frames only (log intensity linear between frame times;
  ``event_subframes=0``);
* ``raycast K``: K sub-frame renders per frame (what ``event_subframes=K`` does; the default is
  K=8; with the raycast backend the anchoring at the rendered frames changes nothing, with
  Cycles it shifts the raycast sub-frames to the path-traced frames at every frame time);
* ``flow K``: K − 1 images per frame interval warped from the two rendered frames along the exact
  flow with its occlusions (:mod:`kubric.annotations.flow_interpolation`; what
  ``event_interpolation=flow`` does with ``event_subframes=K``) — no extra render.

Errors, against the reference, as fractions of the reference's event count: ``count`` = Σ over
pixels and polarities of |N − N_ref|; ``timing`` = the same over bins of 1/8 frame (an event in
the wrong eighth of a frame counts twice). Cost: CPU-seconds to make the intensity samples
beyond the rendered frames, per frame interval, and that as a multiple of one raycast frame
render measured in the same run. Prints a Markdown table (docs/render-cost.md quotes it).
"""

from __future__ import annotations

import time

import numpy as np
import smoke_mode
from bench_raycast import simulated_scene

from kubric.annotations import event_camera as ev
from kubric.annotations.flow_interpolation import interpolate_sequence
from kubric.recipes.exposure_options import ExposureOptions
from kubric.renderer.raycast_subframes import subframe_layers

SIZE = smoke_mode.size(96, 16)
FRAMES = smoke_mode.size(6, 2)
K_REF = smoke_mode.size(32, 4)
KS = smoke_mode.size((2, 4, 8), (2,))
DEFAULT_K = ExposureOptions.event_subframes.default  # the recipes' default
BINS_PER_FRAME = 8


def _cpu() -> float:
    return time.process_time()


def _sub(scene, frames, k):
    """(samples (N, H, W, 3) uint8, frame times (N,)) of k raycast sub-frames per interval."""
    rgb = subframe_layers(scene, frames[:-1], np.arange(k) / k, ("rgba",))["rgba"][..., :3]
    last = subframe_layers(scene, frames[-1:], [0.0], ("rgba",))["rgba"][0, :, ..., :3]
    rgb = np.concatenate([rgb.reshape((-1,) + rgb.shape[2:]), last])
    return rgb, frames[0] + np.arange(len(rgb)) / k


def _histogram(events, h, w, t0, t1, bins):
    """(2, bins, H, W) counts of ON / OFF events per time bin."""
    edges = np.linspace(t0, t1, bins + 1)
    b = np.clip(np.searchsorted(edges, events["t"], side="right") - 1, 0, bins - 1)
    out = np.zeros((2, bins, h, w), np.int64)
    np.add.at(out, (events["p"].astype(np.int64), b, events["y"].astype(np.int64),
                    events["x"].astype(np.int64)), 1)
    return out


def main() -> None:
    scene = simulated_scene("movi_a", SIZE, FRAMES, 3)
    frames = list(range(1, FRAMES + 1))
    model = ev.SensorModel(refractory_us=0.0)
    thresholds = model.thresholds(SIZE, SIZE, np.random.RandomState(0))
    t_us = lambda times: ev.frame_times_us(times, scene.frame_start, scene.frame_rate)  # noqa: E731

    def stream(rgb, times):
        return ev.simulate(ev.srgb_to_log_intensity(np.clip(rgb, 0, 255), model.eps), t_us(times),
                           thresholds, model)

    start = _cpu()
    layers = subframe_layers(scene, frames, [0.0],
                             ("rgba", "forward_flow", "backward_flow", "depth"))
    layers = {k: v[:, 0] for k, v in layers.items()}
    frame_cost = (_cpu() - start) / len(frames)
    ref_rgb, ref_times = _sub(scene, frames, K_REF)
    span = (t_us([frames[0]])[0], t_us([frames[-1]])[0])
    bins = BINS_PER_FRAME * (len(frames) - 1)
    ref = _histogram(stream(ref_rgb, ref_times), SIZE, SIZE, *span, bins)
    total = max(int(ref.sum()), 1)
    rows = []

    def add(name, rgb, times, cost):
        got = _histogram(stream(rgb, times), SIZE, SIZE, *span, bins)
        count = np.abs(got.sum(1) - ref.sum(1)).sum() / total
        timing = np.abs(got - ref).sum() / total
        rows.append((name, int(got.sum()), count, timing, cost, cost / frame_cost))

    add("frames (event_subframes=0)", layers["rgba"][..., :3], np.asarray(frames, float), 0.0)
    for k in KS:
        start = _cpu()
        rgb, times = _sub(scene, frames, k)
        cost = (_cpu() - start - frame_cost * len(frames)) / (len(frames) - 1)
        add(f"raycast K={k}" + (" (default)" if k == DEFAULT_K else ""), rgb, times, max(cost, 0.0))
        start = _cpu()
        warped = interpolate_sequence(layers["rgba"][..., :3], layers["forward_flow"],
                                      layers["backward_flow"], layers["depth"], k)
        cost = (_cpu() - start) / (len(frames) - 1)
        add(f"flow K={k}", warped, frames[0] + np.arange(len(warped)) / k, cost)
    print(f"movi_a seed 3, {SIZE}² px, frames {frames[0]}..{frames[-1]}; reference: raycast "
          f"K={K_REF} ({total} events); one raycast frame render {frame_cost:.3f} CPU-s")
    print("| intensity source | events | count error | timing error (1/8 frame) "
          "| CPU-s per frame interval | × one frame render |")
    print("|---|---|---|---|---|---|")
    for name, n, count, timing, cost, ratio in rows:
        print(f"| {name} | {n} | {count:.3f} | {timing:.3f} | {cost:.4f} | {ratio:.2f} |")


if __name__ == "__main__":
    main()

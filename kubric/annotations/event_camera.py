"""Event-camera streams from intensity at sub-frame times (docs/conventions.md, "Event streams").

Sensor model (:class:`SensorModel`), per pixel, on the log intensity ``L = log(I + eps)`` of the
linear luminance I (Rec. 709 weights of linear RGB in [0, 1]):

* between two consecutive samples (times t0 < t1, µs) L is linear in time;
* each pixel has a reference level ``L_ref``, set to L at the first sample; whenever L crosses
  ``L_ref + C+`` (``L_ref − C−``) an ON (OFF) event fires at the crossing time and ``L_ref``
  moves by ``+C+`` (``−C−``), so between any two times the events' polarity × threshold sums to
  the change of ``L_ref`` and stays within one threshold of the change of L;
* the thresholds are per pixel: ``C± ~ N(contrast±, threshold_spread)`` drawn from the given
  rng, clipped to ≥ ``min_threshold``;
* refractory period R µs: an event less than R after the pixel's last *emitted* event is dropped
  (``L_ref`` still moves: the dropped change is not reported later);
* optional noise (``noise_rate_hz`` > 0): per pixel a Poisson process of that rate over the
  stream's time span, each noise event ON or OFF with probability ½, from the given rng
  (:func:`add_noise`); noise events do not move the reference level.

Sources of sub-frame intensity: the rendered frames alone (L interpolated linearly between frame
times: cheapest, blind to motion inside a frame) or K sub-frame renders per frame (e.g. the
raycast backend's, :func:`kubric.renderer.raycast_subframes.subframe_layers`).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from kubric.core.color import srgb_to_linear

#: Rec. 709 luminance of linear RGB
LUMINANCE = np.array([0.2126, 0.7152, 0.0722])


@dataclasses.dataclass(frozen=True)
class SensorModel:
    """An event sensor (module doc). Thresholds in log-intensity units, times in µs."""

    contrast_pos: float = 0.2
    contrast_neg: float = 0.2
    threshold_spread: float = 0.03
    min_threshold: float = 0.01
    refractory_us: float = 0.0
    eps: float = 1e-3
    noise_rate_hz: float = 0.0

    def __post_init__(self):
        for name in ("contrast_pos", "contrast_neg", "min_threshold", "eps"):
            if not getattr(self, name) > 0:
                raise ValueError(f"SensorModel: {name} must be > 0, got {getattr(self, name)!r}")
        for name in ("threshold_spread", "refractory_us", "noise_rate_hz"):
            if not getattr(self, name) >= 0:
                raise ValueError(f"SensorModel: {name} must be ≥ 0, got {getattr(self, name)!r}")

    def thresholds(self, height: int, width: int, rng) -> np.ndarray:
        """(2, H, W) per-pixel (C+, C−) drawn from ``rng`` (C+ first, then C−)."""
        draws = rng.normal(0.0, 1.0, size=(2, height, width)) * self.threshold_spread
        nominal = np.array([self.contrast_pos, self.contrast_neg])[:, None, None]
        return np.maximum(nominal + draws, self.min_threshold)


def srgb_to_log_intensity(rgb, eps: float) -> np.ndarray:
    """(..., 3) uint8 sRGB → (...) float64 log(luminance + eps) of the linear values."""
    return np.log(srgb_to_linear(np.asarray(rgb, np.float64) / 255.0) @ LUMINANCE + eps)


def simulate(log_intensity, times_us, thresholds, model: SensorModel) -> dict[str, np.ndarray]:
    """Events of log-intensity samples (N, H, W) at increasing ``times_us`` (N,) with per-pixel
    ``thresholds`` (2, H, W). Returns {"x", "y", "t" (µs, float64), "p" (1 = ON, 0 = OFF)},
    sorted by time."""
    levels = np.asarray(log_intensity, np.float64)
    times = np.asarray(times_us, np.float64)
    if levels.ndim != 3 or times.shape != levels.shape[:1] or np.any(np.diff(times) <= 0):
        raise ValueError(f"events: need (N, H, W) samples at N increasing times, got "
                         f"{levels.shape} and {times.shape}")
    h, w = levels.shape[1:]
    c_pos, c_neg = (np.asarray(c, np.float64).ravel() for c in thresholds)
    ref = levels[0].ravel().copy()
    last = np.full(h * w, -np.inf)
    parts = []
    for i in range(len(times) - 1):
        l0, l1 = levels[i].ravel(), levels[i + 1].ravel()
        t0, t1 = times[i], times[i + 1]
        up = l1 >= ref
        step = np.where(up, c_pos, c_neg)
        count = np.floor(np.abs(l1 - ref) / step).astype(np.int64)
        pix = np.flatnonzero(count)
        if pix.size:
            n = count[pix]
            sign = np.where(up[pix], 1.0, -1.0)
            first = ref[pix] + sign * step[pix]  # level of the first crossing
            slope = (l1[pix] - l0[pix]) / (t1 - t0)  # per µs, never 0 where count > 0
            t_first = t0 + (first - l0[pix]) / slope
            spacing = step[pix] / np.abs(slope)
            j0 = np.maximum(0, np.ceil((last[pix] + model.refractory_us - t_first) / spacing))
            stride = np.maximum(1, np.ceil(model.refractory_us / spacing)) \
                if model.refractory_us > 0 else np.ones(pix.size)
            kept = np.where(j0 < n, np.ceil((n - j0) / stride), 0).astype(np.int64)
            owner = np.repeat(np.arange(pix.size), kept)
            starts = np.cumsum(kept) - kept
            j = j0[owner] + (np.arange(owner.size) - starts[owner]) * stride[owner]
            t = np.minimum(t_first[owner] + j * spacing[owner], t1)
            parts.append((pix[owner], t, up[pix][owner]))
            has = kept > 0
            last[pix[has]] = t_first[has] + (j0[has] + (kept[has] - 1) * stride[has]) \
                * spacing[has]
            ref[pix] += sign * n * step[pix]
    if parts:
        pix, t, p = (np.concatenate(a) for a in zip(*parts, strict=True))
    else:
        pix, t, p = np.zeros(0, np.int64), np.zeros(0), np.zeros(0, bool)
    order = np.argsort(t, kind="stable")
    y, x = np.divmod(pix[order], w)
    return {"x": x.astype(np.uint16), "y": y.astype(np.uint16), "t": t[order],
            "p": p[order].astype(np.uint8)}


def add_noise(events: dict, height: int, width: int, t0_us: float, t1_us: float,
              model: SensorModel, rng) -> dict[str, np.ndarray]:
    """``events`` plus ``model.noise_rate_hz`` Poisson noise events per pixel over [t0, t1] µs
    (uniform times, random polarity, from ``rng``), sorted by time."""
    if model.noise_rate_hz <= 0:
        return events
    counts = rng.poisson(model.noise_rate_hz * (t1_us - t0_us) * 1e-6, size=height * width)
    pix = np.repeat(np.arange(height * width), counts)
    t = rng.uniform(t0_us, t1_us, size=pix.size)
    p = rng.randint(0, 2, size=pix.size).astype(np.uint8)
    y, x = np.divmod(pix, width)
    merged = {"x": np.concatenate([events["x"], x.astype(np.uint16)]),
              "y": np.concatenate([events["y"], y.astype(np.uint16)]),
              "t": np.concatenate([events["t"], t]), "p": np.concatenate([events["p"], p])}
    order = np.argsort(merged["t"], kind="stable")
    return {k: v[order] for k, v in merged.items()}


def frame_times_us(frames, frame_start: int, frame_rate: float) -> np.ndarray:
    """Times (µs) of (fractional) frames, 0 at ``frame_start``."""
    return (np.asarray(frames, np.float64) - frame_start) / float(frame_rate) * 1e6

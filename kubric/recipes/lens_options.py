"""The recipes' lens options (``lens``, ``lens_coefficients``, ``lens_coefficients_high``): a
camera lens model of :mod:`kubric.core.lenses` (OpenCV's conventions; docs/conventions.md).

* ``lens=none`` (default): the pinhole camera, nothing drawn, the scene unchanged.
* ``lens=opencv`` (Brown–Conrady) or ``lens=fisheye`` (Kannala–Brandt), with
  ``lens_coefficients`` in OpenCV's order (opencv: ``k1,k2,p1,p2[,k3[,k4,k5,k6]]``; fisheye:
  ``k1,k2,k3,k4``; default :data:`DEFAULT_COEFFICIENTS`). With ``lens_coefficients_high`` (the
  same count) every coefficient is drawn per scene, uniformly between the two values, from the
  scene's rng *after* every other draw of the scene (so the rest of the scene does not change).

The lens needs a backend with the ``lenses`` capability (raycast); others refuse in one line.
"""

from __future__ import annotations

import numpy as np

from kubric.core import lenses
from kubric.pipeline import Option, OptionError

#: the coefficients of ``lens=opencv`` / ``lens=fisheye`` when none are given (a moderate barrel
#: lens; a 4-term fisheye), OpenCV's order
DEFAULT_COEFFICIENTS = {"opencv": (-0.25, 0.07, 0.0, 0.0, -0.008),
                        "fisheye": (0.05, -0.01, 0.002, -0.0004)}


def float_list(value) -> tuple[float, ...]:
    """Converter for numbers separated by commas (``"-0.2,0.05,0,0"``) or a sequence."""
    if isinstance(value, str):
        value = [v for v in value.split(",") if v.strip()]
    try:
        out = tuple(float(v) for v in value)
    except (TypeError, ValueError):
        raise ValueError("expected numbers separated by commas") from None
    if not out or not all(np.isfinite(out)):
        raise ValueError("expected finite numbers separated by commas")
    return out


float_list.allowed = "finite numbers separated by commas, e.g. -0.25,0.07,0,0"


class LensOptions:
    """Mixin of a recipe with a camera: the lens options (module doc)."""

    lens = Option("none", "camera lens model: none (pinhole), opencv (Brown-Conrady), fisheye "
                  "(Kannala-Brandt); OpenCV's conventions", choices=tuple(lenses.MODELS))
    lens_coefficients = Option(None, "lens coefficients in OpenCV's order (opencv: k1,k2,p1,p2"
                               "[,k3[,k4,k5,k6]]; fisheye: k1,k2,k3,k4); default: "
                               + "; ".join(f"{k}: {','.join(str(x) for x in v)}"
                                           for k, v in DEFAULT_COEFFICIENTS.items()),
                               type=float_list)
    lens_coefficients_high = Option(None, "with it, each coefficient is drawn per scene "
                                    "uniformly between lens_coefficients and this",
                                    type=float_list)

    def lens_requests(self) -> dict[str, str]:
        """The backend capability a lens asks for (for ``renderer_requests``)."""
        return {"lenses": f"lens={self.lens}"} if self.lens != "none" else {}

    def check_lens(self) -> None:
        """Bad lens options fail here, before anything renders (one line)."""
        low, high = self.lens_coefficients, self.lens_coefficients_high
        if self.lens == "none":
            given = [n for n, v in (("lens_coefficients", low), ("lens_coefficients_high", high))
                     if v is not None]
            if given:
                raise OptionError(f"{self.name}: option {given[0]} needs lens=opencv or "
                                  "lens=fisheye, got lens=none")
            return
        low = DEFAULT_COEFFICIENTS[self.lens] if low is None else low
        if high is not None and (len(high) != len(low) or
                                 any(h < lo for lo, h in zip(low, high, strict=True))):
            raise OptionError(f"{self.name}: option lens_coefficients_high="
                              f"{','.join(map(str, high))} must have the {len(low)} values of "
                              f"lens_coefficients, each ≥ its low value {list(low)}")
        for what, values in (("lens_coefficients", low), ("lens_coefficients_high", high)):
            if values is None:
                continue
            try:
                lenses.from_record(self.lens, values)
            except ValueError as err:
                raise OptionError(f"{self.name}: option {what}={','.join(map(str, values))}: "
                                  f"{err}") from None

    def make_lens(self, rng) -> lenses.Lens:
        """The scene's lens (draws from ``rng`` only with ``lens_coefficients_high``)."""
        if self.lens == "none":
            return lenses.PINHOLE
        low = self.lens_coefficients or DEFAULT_COEFFICIENTS[self.lens]
        if self.lens_coefficients_high is None:
            return lenses.from_record(self.lens, low)
        return lenses.from_record(self.lens, rng.uniform(low, self.lens_coefficients_high))

"""Texture-structure NeRF: ``texture_nerf`` (the paper's "Texture-structure in NeRF").

About 30 small cubes stand on a grey floor (CLEVR lamps); each cube has its own procedural texture,
band-limited noise with a known **cut-off frequency** ``f_c = 10^U(band_range)`` in cycles per
cube face (default 10^U(−1, 2)): the same texture image on each of the six faces, each face mapped
to the whole image, so a face of edge e metres shows ``f_c / e`` cycles per metre.

Texture (:func:`band_limited_texture`): on a ``texture_size``² grid, every 2D frequency
``k = (k_u, k_v)`` (integer cycles per face) with ``|k| ≤ f_c`` gets an independent complex normal
coefficient, the others zero; the real part of the inverse FFT, scaled to a standard deviation of
``TEXTURE_AMPLITUDE``, is added to a random base colour (per channel, sRGB, clipped to [0, 1]).
So the power spectrum is flat up to ``f_c`` and zero above (a cut-off below 1 cycle leaves only the
base colour: a flat face). ``f_c`` must stay below the texture's Nyquist limit
``texture_size / 2`` (checked before rendering).

Per view it writes ``cutoff_{i:05d}.tiff`` (float32: the cut-off of the cube the pixel sees, 0 on
floor / background) and ``band_{i:05d}.png`` (band label: 0 = no cube, k = the k-th interval of
``metadata.bands``, intervals of ``band_width`` decades from ``10^band_range[0]``). Instances get
``cutoff_frequency`` and ``band``.
"""

from __future__ import annotations

import math

import numpy as np

import kubric as kb
from kubric.io import png_io
from kubric.io.paths import atomic_write_bytes
from kubric.pipeline import Option, OptionError, float_range
from kubric.recipes import multiview_schema
from kubric.recipes.multiview_base import ExtraOutputs, MultiviewBase

TEXTURE_AMPLITUDE = 0.12
CUBE_ID = "textured_cube"

# A unit cube (±0.5 m) whose six faces each map to the whole texture: (normal, u axis, v axis).
_FACES = [((0, -1, 0), (1, 0, 0), (0, 0, 1)), ((1, 0, 0), (0, 1, 0), (0, 0, 1)),
          ((0, 1, 0), (-1, 0, 0), (0, 0, 1)), ((-1, 0, 0), (0, -1, 0), (0, 0, 1)),
          ((0, 0, 1), (1, 0, 0), (0, 1, 0)), ((0, 0, -1), (1, 0, 0), (0, -1, 0))]


def cube_obj_text() -> str:
    """OBJ text of the unit cube with per-face UVs [0, 1]²: on the face of normal n with axes
    (a_u, a_v), the point 0.5·n + (u − 0.5)·a_u + (v − 0.5)·a_v has texture coordinate (u, v)."""
    lines, faces = [], []
    for f, (n, au, av) in enumerate(_FACES):
        n, au, av = (np.asarray(x, float) for x in (n, au, av))
        for u, v in ((0, 0), (1, 0), (1, 1), (0, 1)):
            p = 0.5 * n + (u - 0.5) * au + (v - 0.5) * av
            lines.append("v {:.6f} {:.6f} {:.6f}".format(*p))
        faces.append(f)
    lines += ["vt 0 0", "vt 1 0", "vt 1 1", "vt 0 1"]
    lines += [f"vn {n[0]} {n[1]} {n[2]}" for n, _, _ in _FACES]
    for f in faces:
        b = 4 * f
        lines.append(f"f {b + 1}/1/{f + 1} {b + 2}/2/{f + 1} {b + 3}/3/{f + 1} {b + 4}/4/{f + 1}")
    return "\n".join(lines) + "\n"


def textured_cube(directory, size: float, texture_png):
    """A :class:`kubric.FileBasedObject` unit cube (scaled by ``size``) with the texture file."""
    path = directory / f"{CUBE_ID}.obj"
    if not path.is_file():
        atomic_write_bytes(cube_obj_text().encode(), path)
    obj = kb.FileBasedObject(asset_id=CUBE_ID, render_filename=str(path),
                             render_import_kwargs={"forward_axis": "Y", "up_axis": "Z"},
                             bounds=((-0.5, -0.5, -0.5), (0.5, 0.5, 0.5)), scale=size,
                             mass=size ** 3)
    texture = kb.Texture(filename=str(texture_png), mapping="uv")
    obj.material = kb.PrincipledBSDFMaterial(color=texture, roughness=1.0, specular=0.0)
    return obj


def band_limited_texture(rng, size: int, cutoff: float, base_rgb) -> np.ndarray:
    """(size, size, 3) float in [0, 1]: band-limited noise of cut-off ``cutoff`` cycles per image
    side around ``base_rgb`` (see module doc)."""
    k = np.fft.fftfreq(size) * size
    inside = np.hypot(k[:, None], k[None, :]) <= cutoff
    inside[0, 0] = False
    out = np.empty((size, size, 3))
    for c in range(3):
        coeffs = (rng.standard_normal((size, size)) + 1j * rng.standard_normal((size, size)))
        noise = np.real(np.fft.ifft2(np.where(inside, coeffs, 0.0)))
        std = noise.std()
        out[..., c] = base_rgb[c] + (noise / std * TEXTURE_AMPLITUDE if std > 0 else 0.0)
    return np.clip(out, 0.0, 1.0)


def band_edges(band_range, band_width: float) -> np.ndarray:
    """(B, 2) cut-off intervals [10^a, 10^b) of ``band_width`` decades covering ``band_range``."""
    low, high = band_range
    count = max(1, math.ceil((high - low) / band_width - 1e-9))
    exps = low + band_width * np.arange(count + 1)
    return np.stack([10.0 ** exps[:-1], 10.0 ** exps[1:]], axis=1)


def band_of(cutoff: float, band_range, band_width: float) -> int:
    """The band label (1-based) of a cut-off."""
    count = len(band_edges(band_range, band_width))
    k = int(math.floor((math.log10(cutoff) - band_range[0]) / band_width))
    return min(max(k, 0), count - 1) + 1


class TextureNerf(MultiviewBase, name="texture_nerf"):
    """Texture-structure NeRF: ~30 small cubes with band-limited textures of known cut-off."""

    schema = multiview_schema.TEXTURE_NERF

    num_objects = Option(30, "number of cubes", low=1, high=200)
    size_range = Option((0.4, 0.7), "cube edge (m) low,high", type=float_range, low=0.05, limit=100.0)
    band_range = Option((-1.0, 2.0), "log10 of the texture cut-off (cycles per face) low,high",
                        type=float_range, low=-3.0, high=6.0)
    band_width = Option(0.5, "width of a band label interval (decades)", low=0.01)
    texture_size = Option(256, "texture pixels per face side", low=8, high=4096)
    region = Option(3.0, "cubes stand in the square ±region (m) of the floor", low=0.5)
    camera_distance = Option((6.5, 8.5), MultiviewBase.camera_distance.help, type=float_range,
                             low=0.1)

    def check(self):
        super().check()
        nyquist = self.texture_size / 2
        top = 10.0 ** self.band_range[1]
        if top > nyquist:
            raise OptionError(
                f"{self.name}: option band_range={self.band_range[0]},{self.band_range[1]} "
                f"reaches {top:.4g} cycles per face, beyond the {nyquist:g} that "
                f"texture_size={self.texture_size} can render (Nyquist: texture_size / 2); "
                f"lower band_range to ≤ {math.log10(nyquist):.3f} or raise texture_size")

    def build_background(self, scene, rng, sources):
        scene.metadata["bands"] = band_edges(self.band_range, self.band_width)
        return self.grey_background(scene, rng, sources)

    def add_objects(self, scene, rng, sources):
        occupied = []
        for k in range(self.num_objects):
            size = float(rng.uniform(*self.size_range))
            cutoff = float(10.0 ** rng.uniform(*self.band_range))
            base = kb.random_hue_color(saturation=0.6, value=0.6, rng=rng)
            texture = band_limited_texture(rng, self.texture_size, cutoff, base.rgb)
            path = self.scratch / f"texture_{k:03d}.png"
            png_io.write_png(np.rint(texture * 255).astype(np.uint8), path)
            obj = textured_cube(self.scratch, size, path)
            obj.metadata = {"size": size, "cutoff_frequency": cutoff,
                            "band": band_of(cutoff, self.band_range, self.band_width)}
            self.add_upright(scene, obj, rng, occupied, self.region)

    def extra_outputs(self, scene, layers, instances, meta):
        seg = layers["segmentation"]
        cutoff = np.zeros(len(instances) + 1, np.float32)
        band = np.zeros(len(instances) + 1, np.uint32)
        for k, info in enumerate(instances, start=1):
            cutoff[k], band[k] = info["cutoff_frequency"], info["band"]
        return ExtraOutputs(layers={"band": band[seg], "cutoff": cutoff[seg]})

"""The exact annotation recipe: how ``depth``, ``z``, ``segmentation``, flow, ``normal``,
``object_coordinates`` and ``uv`` are rendered and decoded.

Why a separate render: Cycles writes its data passes (normal, UV, vector, AOVs) as the *average*
over all samples of a pixel, and the samples spread over the pixel filter (1.5 px wide by
default), so at object edges these passes blend neighbouring surfaces (measured: thousands of
wrong normal pixels and flow off by up to 6 px at 64 spp). A pixel-centre value needs one sample
through the pixel centre.

Recipe (chosen as the cheapest exact one; measured ≈ 0.2–0.3 CPU-s per 256² frame, independent of
the RGB sample count):
  1. The RGB render runs at the requested samples with only the Combined pass.
  2. The annotation render runs once over the same frames with: 1 sample, pixel filter width 0.01
     px (the sample lands within 0.005 px of the pixel centre), no light bounces, no denoising,
     no motion blur and no depth of field (pinhole pixel-centre rays), and a view-layer material
     override whose surface is black emission (nothing to shade, no light sampling) and which
     writes the shaded point's *object-space* coordinate (Texture Coordinate → Object: the
     unscaled local frame of the model) into a colour AOV named ``object_coordinates``.
     Passes: Depth, Object Index (each object's ``pass_index`` = its position in scene.assets + 1,
     unique, mapped to segmentation labels afterwards), Normal, Vector, UV and the AOV, written as a
     float32 multilayer EXR per frame and read back with OpenEXR.
  3. Decoding (numpy):
     * Cycles' Depth pass is the distance along the view axis (``z``); ``depth`` is converted with
       kubric.core.camera_geometry.z_to_depth (orthographic: the same). Pixels whose ray hits
       nothing get BACKGROUND_DEPTH in both.
     * segmentation: object index → label (``segmentation_id`` if set, else index); 0 = nothing.
     * Vector pass (4 channels, pixels, Blender's image axes x right, y up), measured: channels
       0–1 are (position in the previous frame − position now), channels 2–3 are (position now −
       position in the next frame). Hence, as (Δrow, Δcol) with rows going down:
       backward_flow = (−v[1], v[0]) and forward_flow = (v[3], −v[2]). Verified by
       tests/test_renderer_geometry.py against flow computed from the model's keyframes and
       camera matrices (moving object and moving camera). Outside the keyed range Blender's
       F-curves hold the end values, as the model does, so flow there is from held poses.
     * normal: world-space shading normal (smooth for spheres), 0 on background.
     * object_coordinates: (p_local − bounds_min) / (bounds_max − bounds_min) per object with the
       model's unscaled local bounds, clipped to [0, 1]; 0 on background. For a skinned
       character p_local is the **rest-pose** surface point (model frame, from the mesh's
       ``kubric_rest_position`` attribute, interpolated over the triangle like the Generated
       coordinate) and the bounds are its rest bounds: the value names the surface point, not
       where the deformation moved it (docs/characters.md).
     * uv: (u, v, 0) from the UV pass (the mesh's first UV map), wrapped into [0, 1) as a
       repeating texture lookup sees them (meshes may tile textures with UV > 1); 0 on background.
"""

from __future__ import annotations

import numpy as np

from kubric.core import camera_geometry as geo
from kubric.renderer.base import ALL_LAYERS, ANNOTATION_LAYERS  # noqa: F401  (their old home)

AOV_NAME = "object_coordinates"
#: Cycles writes 1e10 where a ray hits nothing; anything beyond this is background.
_NO_HIT = 1e9


def override_material():
    """The annotation render's material override (black emission + object-coordinate AOV)."""
    import bpy
    mat = bpy.data.materials.get("kubric_annotations")
    if mat is not None:
        return mat
    mat = bpy.data.materials.new("kubric_annotations")
    nodes, links = mat.node_tree.nodes, mat.node_tree.links
    nodes.clear()
    out = nodes.new("ShaderNodeOutputMaterial")
    diffuse = nodes.new("ShaderNodeBsdfDiffuse")
    diffuse.inputs["Color"].default_value = (0.0, 0.0, 0.0, 1.0)
    links.new(diffuse.outputs["BSDF"], out.inputs["Surface"])
    coords = nodes.new("ShaderNodeTexCoord")
    aov = nodes.new("ShaderNodeOutputAOV")
    aov.aov_name = AOV_NAME
    # characters (kubric.renderer.blender_characters) carry their rest-pose vertex in a point
    # attribute and a flag attribute = 1: their AOV is the rest-pose surface point (model frame);
    # on every other mesh the attributes are absent (read as 0) and the AOV is the object point.
    rest = nodes.new("ShaderNodeAttribute")
    rest.attribute_name = "kubric_rest_position"
    flag = nodes.new("ShaderNodeAttribute")
    flag.attribute_name = "kubric_skinned"
    mix = nodes.new("ShaderNodeMix")
    mix.data_type = "VECTOR"
    sockets = {s.identifier: s for s in mix.inputs}
    links.new(flag.outputs["Fac"], sockets["Factor_Float"])
    links.new(coords.outputs["Object"], sockets["A_Vector"])
    links.new(rest.outputs["Vector"], sockets["B_Vector"])
    out_vec = next(s for s in mix.outputs if s.identifier == "Result_Vector")
    links.new(out_vec, aov.inputs["Color"])
    return mat


def read_multilayer_exr(path) -> dict[str, np.ndarray]:
    """Read a Blender 5 multilayer EXR: ``{pass name: (H, W, C) float32}``.

    Blender 5 writes one EXR part per pass, channels named ``<layer>.<pass>.<component>``; the
    components are returned in the file's channel order sorted by Blender's component letters
    (X Y Z W / R G B A / U V A: alpha always after the colour or UV components).
    """
    import OpenEXR
    order = {c: i for i, c in enumerate("XYZWRGBUVA")}
    passes: dict[str, dict[str, np.ndarray]] = {}
    with OpenEXR.File(str(path), separate_channels=True) as f:
        for part in f.parts:
            for name, channel in part.channels.items():
                pieces = name.split(".")
                pass_name = pieces[-2] if len(pieces) >= 2 else pieces[0]
                comp = pieces[-1]
                passes.setdefault(pass_name, {})[comp] = np.asarray(channel.pixels,
                                                                     dtype=np.float32)
    out = {}
    for pass_name, comps in passes.items():
        keys = sorted(comps, key=lambda c: order.get(c, 99))
        out[pass_name] = np.stack([comps[k] for k in keys], axis=-1)
    return out


def _find(passes, *names):
    for n in names:
        if n in passes:
            return passes[n]
    raise KeyError(f"annotation EXR lacks pass {names[0]!r}; it has {sorted(passes)}")


def decode(passes, camera, frame, label_lut, bounds_lut, wanted) -> dict[str, np.ndarray]:
    """Turn one frame's EXR passes into the requested layers (each (H, W, C)).

    Args:
      passes: from :func:`read_multilayer_exr`.
      camera: the model camera (for z → depth at ``frame``).
      label_lut: (N+1,) uint32, object index → segmentation label (0 → 0).
      bounds_lut: (N+1, 2, 3) float64 unscaled local bounds per object index.
      wanted: layer names to return.
    """
    z = _find(passes, "Depth", "Z")[..., :1].astype(np.float32)
    hit = z[..., 0] < _NO_HIT
    index = np.rint(_find(passes, "Object Index", "IndexOB")[..., 0]).astype(np.int64)
    index = np.where(hit, np.clip(index, 0, len(label_lut) - 1), 0)
    out = {}
    if "z" in wanted or "depth" in wanted:
        with camera.at_frame(frame):
            depth = geo.z_to_depth(camera, np.where(hit[..., None], z, 0.0))
        bg = np.float32(geo.BACKGROUND_DEPTH)
        out["z"] = np.where(hit[..., None], z, bg).astype(np.float32)
        out["depth"] = np.where(hit[..., None], depth, bg).astype(np.float32)
    if "segmentation" in wanted:
        out["segmentation"] = label_lut[index][..., None].astype(np.uint32)
    if "forward_flow" in wanted or "backward_flow" in wanted:
        v = _find(passes, "Vector").astype(np.float32)
        mask = hit[..., None]
        out["backward_flow"] = np.where(mask, np.stack([-v[..., 1], v[..., 0]], -1), 0.0)
        out["forward_flow"] = np.where(mask, np.stack([v[..., 3], -v[..., 2]], -1), 0.0)
    if "normal" in wanted:
        n = _find(passes, "Normal")[..., :3]
        out["normal"] = np.where(hit[..., None], n, 0.0).astype(np.float32)
    if "uv" in wanted:
        uv = _find(passes, "UV")
        res = np.zeros(uv.shape[:2] + (3,), np.float32)
        res[..., :2] = np.mod(uv[..., :2], 1.0)  # the repeat phase: what a texture lookup uses
        out["uv"] = np.where(hit[..., None], res, 0.0).astype(np.float32)
    if "object_coordinates" in wanted:
        p = _find(passes, AOV_NAME)[..., :3].astype(np.float64)
        lo, hi = bounds_lut[index, 0], bounds_lut[index, 1]
        extent = np.where(hi - lo > 0, hi - lo, 1.0)
        oc = np.clip((p - lo) / extent, 0.0, 1.0)
        out["object_coordinates"] = np.where(hit[..., None] & (index[..., None] > 0), oc,
                                             0.0).astype(np.float32)
    return {k: v.astype(np.float32, copy=False) if k != "segmentation" else v
            for k, v in out.items() if k in wanted}

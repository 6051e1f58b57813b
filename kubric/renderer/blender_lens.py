"""Lens models in Cycles: a custom OSL camera (Blender ≥ 5.0) that casts each sample through the
camera's lens model (:mod:`kubric.core.lenses`), so RGB and the exact annotation pass describe
the distorted image, and the annotation decoding that a custom camera needs.

The camera shader receives the sample's raster position (x right, y **up**, in [0, 1]) and
returns the ray in Cycles' camera space (x right, y up, looking down +z). Pixel position
``(x, y) = (rx·W, (1 − ry)·H)`` (y down, centres at +0.5), distorted normalised position
``((x − cx) / fx, (y − cy) / fy)``, then the model's inverse in OSL's 32-bit floats: Newton's
method from a first-order guess, and where that does not converge inside the domain the safe
path of :meth:`kubric.core.lenses.Lens.undistort` (bisection on the radius / angle, then Newton);
a position without a ray
(outside the lens's image) gets throughput 0 (nothing: background in every pass). The shader
also writes the ray's derivatives per image pixel (``dDdx``, ``dDdy``: the inverse Jacobian of
the distortion at the solution; ``dPdx = dPdy = 0``), which Cycles uses for ray differentials
instead of OSL's automatic differentiation of the Newton iterations (that cost up to ~25 % of
a frame). The lens and
the intrinsics are baked into the shader's source (a camera with a lens keeps its focal length
and shift: keyframing them is refused).

What a custom camera changes in the annotation pass (measured with a pinhole-formula shader
against Blender's own perspective camera: identical labels, and): Cycles' Depth pass holds the
**distance** along the ray (not z), and its Vector pass is not a motion vector (Cycles cannot
project through a custom camera). So :func:`lens_layers` takes ``depth`` from the Depth pass,
``z`` = :func:`~kubric.core.camera_geometry.depth_to_z`, and the flow as the raycast backend does:
the surface point of the ``object_coordinates`` AOV (the object's unscaled local frame) moved with
its object's pose at t ± 1 and projected through the lens. On a skinned character the AOV is the
rest-pose point: :func:`rest_anchors` finds its (triangle, barycentric) on the rest mesh and the
point moves with the skinned mesh (``Character.surface_points`` at t ± 1).
"""

from __future__ import annotations

import glob
import os
import sys

import numpy as np

from kubric.core import camera_geometry as geo
from kubric.core import lenses
from kubric.core.deformables import DEFORMING

_TEXT_NAME = "kubric_lens.osl"

#: the shader's start: the sample's distorted normalised position (xd, yd), its radius rd
_HEADER = """
shader kubric_lens(output point position = 0, output vector direction = 0,
                   output color throughput = 1%(derivative_outputs)s)
{
    point rp = camera_shader_raster_position();
    float xd = (rp[0] * %(w)d - %(cx)r) / %(fx)r;
    float yd = ((1.0 - rp[1]) * %(h)d - %(cy)r) / %(fy)r;
    float rd = hypot(xd, yd);
    float edge = %(edge)r;
"""

_BROWN = """
float kb_ratio(float r2) {
    return (1.0 + r2 * (%(k1)r + r2 * (%(k2)r + r2 * %(k3)r)))
         / (1.0 + r2 * (%(k4)r + r2 * (%(k5)r + r2 * %(k6)r)));
}
// the distortion at (a, b): radial ratio q, its denominator den and the (symmetric) Jacobian
void kb_jacobian(float a, float b, output float q, output float den, output float j00,
                 output float j01, output float j11) {
    float r2 = a * a + b * b;
    float num = 1.0 + r2 * (%(k1)r + r2 * (%(k2)r + r2 * %(k3)r));
    den = 1.0 + r2 * (%(k4)r + r2 * (%(k5)r + r2 * %(k6)r));
    float dnum = %(k1)r + r2 * (2.0 * %(k2)r + 3.0 * r2 * %(k3)r);
    float dden = %(k4)r + r2 * (2.0 * %(k5)r + 3.0 * r2 * %(k6)r);
    q = num / den;
    float dq = (dnum * den - num * dden) / (den * den);
    j00 = q + 2.0 * a * a * dq + 2.0 * %(p1)r * b + 6.0 * %(p2)r * a;
    j01 = 2.0 * a * b * dq + 2.0 * %(p1)r * a + 2.0 * %(p2)r * b;
    j11 = q + 2.0 * b * b * dq + 6.0 * %(p1)r * b + 2.0 * %(p2)r * a;
}
// n Newton steps on the full model from (a, b); res: the residual before the last step
void kb_newton(float xd, float yd, int n, output float a, output float b, output float res,
               output float ok) {
    res = 1.0;
    ok = 0.0;
    for (int i = 0; i < n; i++) {
        float r2 = a * a + b * b;
        float q, den, j00, j01, j11;
        kb_jacobian(a, b, q, den, j00, j01, j11);
        float ex = a * q + 2.0 * %(p1)r * a * b + %(p2)r * (r2 + 2.0 * a * a) - xd;
        float ey = b * q + %(p1)r * (r2 + 2.0 * b * b) + 2.0 * %(p2)r * a * b - yd;
        float det = j00 * j11 - j01 * j01;
        res = max(fabs(ex), fabs(ey));
        ok = (det > 0.0 && den > 0.0) ? 1.0 : 0.0;
        if (ok == 0.0) break;
        a -= (j11 * ex - j01 * ey) / det;
        b -= (j00 * ey - j01 * ex) / det;
    }
}
""" + _HEADER + """    float tol = 1e-5 * max(1.0, rd);
    // fast path: Newton from the first-order inverse
    float q0 = kb_ratio(rd * rd);
    float a = xd / q0, b = yd / q0, res, ok;
    kb_newton(xd, yd, 5, a, b, res, ok);
    if (ok == 0.0 || !(res < tol) || !(hypot(a, b) < edge)) {
        // safe path: the radius by bisection on the increasing radial map, then Newton
        float lo = 0.0, hi = edge;
        if (rd >= edge * kb_ratio(edge * edge)) { lo = edge * 0.999999; hi = lo; }
        for (int i = 0; i < 28; i++) {
            float mid = 0.5 * (lo + hi);
            if (mid * kb_ratio(mid * mid) < rd) lo = mid; else hi = mid;
        }
        float r = 0.5 * (lo + hi);
        a = rd > 0.0 ? xd * r / rd : 0.0;
        b = rd > 0.0 ? yd * r / rd : 0.0;
        kb_newton(xd, yd, 6, a, b, res, ok);
    }
    if (ok == 0.0 || !(res < 10.0 * tol) || !(hypot(a, b) < edge)) throughput = color(0.0);
    direction = normalize(vector(a, -b, 1.0));
%(brown_derivatives)s}
"""

#: the ray's derivatives per image pixel, written out so that OSL does not differentiate the
#: Newton iterations itself (its automatic derivatives cost ~15 % of a 256² frame): d(a, b) /
#: d(xd, yd) is the inverse Jacobian of the distortion at the solution
_BROWN_DERIVATIVES = """    {
        float q, den, j00, j01, j11;
        kb_jacobian(a, b, q, den, j00, j01, j11);
        float det = j00 * j11 - j01 * j01;
        if (det == 0.0) det = 1.0;
        float sx = %(step_x)r / %(fx)r, sy = %(step_y)r / %(fy)r;
        vector u = vector(a, -b, 1.0);
        float n = length(u);
        vector ux = vector(j11 * sx / det, j01 * sx / det, 0.0);
        vector uy = vector(-j01 * sy / det, -j00 * sy / det, 0.0);
        dDdx = (ux - direction * dot(direction, ux)) / n;
        dDdy = (uy - direction * dot(direction, uy)) / n;
    }
"""

_FISHEYE_DERIVATIVES = """    {
        // D = (m xd, -m yd, cos t) with m = sin(t) / rd and dt/drd = 1 / slope(t)
        float sx = %(step_x)r / %(fx)r, sy = %(step_y)r / %(fy)r;
        float m = 1.0, dm = 0.0, dt = 1.0 / kb_slope(t);
        if (rd > 1e-6) {
            m = sin(t) / rd;
            dm = (cos(t) * dt * rd - sin(t)) / (rd * rd);
        }
        float gx = rd > 1e-6 ? xd / rd : 0.0, gy = rd > 1e-6 ? yd / rd : 0.0;
        // partials of (m xd, -m yd, cos t) in xd and in yd
        vector px = vector(m + xd * dm * gx, -yd * dm * gx, -sin(t) * dt * gx);
        vector py = vector(xd * dm * gy, -(m + yd * dm * gy), -sin(t) * dt * gy);
        vector u = vector(m * xd, -m * yd, cos(t));
        float n = length(u);
        vector D = u / n;
        vector ex = px * sx, ey = py * sy;
        dDdx = (ex - D * dot(D, ex)) / n;
        dDdy = (ey - D * dot(D, ey)) / n;
    }
"""

#: the derivative outputs Cycles reads instead of OSL's automatic derivatives (all four or none)
_DERIVATIVE_OUTPUTS = (",\n                   output vector dPdx = 0, output vector dPdy = 0,"
                       "\n                   output vector dDdx = 0, output vector dDdy = 0")

_FISHEYE = """
float kb_theta_d(float t) {
    float t2 = t * t;
    return t * (1.0 + t2 * (%(k1)r + t2 * (%(k2)r + t2 * (%(k3)r + t2 * %(k4)r))));
}
float kb_slope(float t) {
    float t2 = t * t;
    return 1.0 + t2 * (3.0 * %(k1)r + t2 * (5.0 * %(k2)r + t2 * (7.0 * %(k3)r + t2 * 9.0 * %(k4)r)));
}
""" + _HEADER + """    if (rd >= kb_theta_d(edge)) throughput = color(0.0);
    float t = rd;  // fast path: Newton from theta = theta_d
    float err = 1.0;
    for (int i = 0; i < 5; i++) {
        err = kb_theta_d(t) - rd;
        t -= err / kb_slope(t);
    }
    if (!(fabs(err) < 1e-5 * max(1.0, rd)) || !(t >= 0.0 && t < edge)) {
        float lo = 0.0, hi = edge;  // safe path: bisection on theta_d, then Newton
        for (int i = 0; i < 28; i++) {
            float mid = 0.5 * (lo + hi);
            if (kb_theta_d(mid) < rd) lo = mid; else hi = mid;
        }
        t = 0.5 * (lo + hi);
        for (int i = 0; i < 2; i++) t -= (kb_theta_d(t) - rd) / kb_slope(t);
    }
    float s = sin(t);
    float ux = rd > 0.0 ? xd / rd : 0.0;
    float uy = rd > 0.0 ? yd / rd : 0.0;
    direction = normalize(vector(s * ux, -s * uy, cos(t)));
%(fisheye_derivatives)s}
"""


#: image-pixel step of the distorted pixel position per unit of Cycles' image X / Y in the
#: derivative outputs (Cycles' ray differentials are per pixel; +Y is up, pixel rows go down)
PIXEL_STEP = (1.0, -1.0)


def osl_source(lens, intrinsics_pixels, resolution, derivatives: bool = True) -> str:
    """The OSL camera shader of ``lens`` with these OpenCV pixel intrinsics (3, 3) and
    (width, height) (see module doc); ``derivatives``: write the ray's derivatives out (module
    doc) rather than leave them to OSL's automatic differentiation."""
    k = np.asarray(intrinsics_pixels, np.float64)
    w, h = (int(v) for v in resolution)
    values = {"w": w, "h": h, "fx": float(k[0, 0]), "fy": float(k[1, 1]), "cx": float(k[0, 2]),
              "cy": float(k[1, 2]), "step_x": PIXEL_STEP[0], "step_y": PIXEL_STEP[1],
              "derivative_outputs": _DERIVATIVE_OUTPUTS if derivatives else ""}
    if isinstance(lens, lenses.Fisheye):
        values.update(k1=lens.k1, k2=lens.k2, k3=lens.k3, k4=lens.k4, edge=lens.max_angle)
        values["fisheye_derivatives"] = _FISHEYE_DERIVATIVES % values if derivatives else ""
        return _FISHEYE % values
    if isinstance(lens, lenses.BrownConrady):
        values.update(dict(zip(lens._names, lens.coefficients, strict=True)),
                      edge=min(lens.domain_radius(), 1e6))
        values["brown_derivatives"] = _BROWN_DERIVATIVES % values if derivatives else ""
        return _BROWN % values
    raise ValueError(f"the blender backend has no OSL camera for lens {lens!r}; allowed: "
                     "BrownConrady, Fisheye")


def _with_oslquery():
    """Cycles' custom-camera update imports ``oslquery``, which the bpy wheel ships in its own
    Python's site-packages (not on the importing interpreter's path)."""
    import bpy
    root = bpy.utils.resource_path("LOCAL")  # .../bpy/5.0
    for path in glob.glob(os.path.join(root, "python", "lib", "python3*", "site-packages")):
        if os.path.isdir(os.path.join(path, "oslquery")) and path not in sys.path:
            sys.path.append(path)


def apply(camera_object, camera, resolution) -> None:
    """Make the Blender camera ``camera_object`` cast through ``camera``'s lens (a custom OSL
    camera), or a plain perspective camera when it has none."""
    import bpy
    data = camera_object.data
    if not geo.has_distortion(camera):
        if data.type == "CUSTOM":
            data.type = "PERSP"
            data.shift_x, data.shift_y = float(camera.shift_x), float(camera.shift_y)
        return
    # Cycles adds the camera's shift to a custom camera's raster position; the shader bakes the
    # principal point (shift included) itself
    data.shift_x = data.shift_y = 0.0
    _with_oslquery()
    text = bpy.data.texts.get(_TEXT_NAME) or bpy.data.texts.new(_TEXT_NAME)
    text.clear()
    text.write(osl_source(geo.lens_of(camera), geo.pixel_intrinsics(camera, resolution),
                          resolution))
    data.type = "CUSTOM"
    data.custom_mode = "INTERNAL"
    data.custom_shader = text  # compiles the shader (Cycles' update callback)
    if not data.custom_bytecode:
        raise RuntimeError(f"camera {camera.name!r}: Cycles did not compile the lens shader")


def lens_layers(passes, camera, frame, assets, wanted) -> dict:
    """depth, z and flow of one frame rendered through a custom lens camera (module doc);
    ``assets``: the scene's assets (object index = position + 1)."""
    from kubric.renderer.blender_passes import _NO_HIT, AOV_NAME, _find
    distance = _find(passes, "Depth", "Z")[..., :1].astype(np.float64)
    hit = distance[..., 0] < _NO_HIT
    index = np.rint(_find(passes, "Object Index", "IndexOB")[..., 0]).astype(np.int64)
    index = np.where(hit, np.clip(index, 0, len(assets)), 0)
    aov = _find(passes, AOV_NAME)[..., :3].astype(np.float64)
    h, w = hit.shape
    out = {}
    bg = geo.BACKGROUND_DEPTH
    if "depth" in wanted or "z" in wanted:
        depth = np.where(hit[..., None], distance, 0.0)
        with camera.at_frame(frame):
            z = geo.depth_to_z(camera, depth)
        out["depth"] = np.where(hit[..., None], depth, bg).astype(np.float32)
        out["z"] = np.where(hit[..., None], z, bg).astype(np.float32)
    centres = geo.pixel_centres(h, w)
    rows, cols = np.nonzero(hit & (index > 0))
    for name, step in (("forward_flow", 1), ("backward_flow", -1)):
        if name not in wanted:
            continue
        moved = np.zeros((len(rows), 3))
        owners = index[rows, cols]
        for i in np.unique(owners):
            sel = owners == i
            asset = assets[i - 1]
            local = aov[rows[sel], cols[sel]]
            if isinstance(asset, DEFORMING):  # the AOV is the rest-pose point: its material point
                tri, bary = rest_anchors(asset, local)
                moved[sel] = asset.surface_points(tri, bary, frame + step)
                continue
            with asset.at_frame(frame + step):
                m = asset.matrix_world
                scale = np.asarray(asset.scale, np.float64)
            moved[sel] = (local * scale) @ m[:3, :3].T + m[:3, 3]
        xy, _ = geo.project_to_pixels(camera, moved, frame=frame + step, resolution=(w, h))
        flow = np.zeros((h, w, 2), np.float32)
        delta = xy - centres[rows, cols]
        flow[rows, cols] = np.nan_to_num(delta[:, ::-1], nan=0.0)  # (Δrow, Δcol)
        out[name] = flow
    return out


def rest_anchors(character, points, candidates: int = 16):
    """(triangle (N,), barycentric (N, 3)) of rest-pose points (N, 3) (model frame) on the
    character's rest mesh: among the ``candidates`` triangles with the nearest centroids, the
    one nearest to the point, and the point's barycentric coordinates on it (clipped to the
    triangle)."""
    from scipy.spatial import cKDTree
    faces = np.asarray(character.faces, np.int64)
    tris = np.asarray(character.vertices, np.float64)[faces]                 # (F, 3, 3)
    k = min(candidates, len(faces))
    _, near = cKDTree(tris.mean(axis=1)).query(points, k=k)
    near = np.asarray(near).reshape(len(points), k)
    best = np.full(len(points), np.inf)
    tri = np.zeros(len(points), np.int64)
    bary = np.zeros((len(points), 3))
    for j in range(k):
        b = _barycentric(tris[near[:, j]], points)
        dist = np.linalg.norm(np.einsum("nk,nkj->nj", b, tris[near[:, j]]) - points, axis=1)
        better = dist < best
        best[better], tri[better], bary[better] = dist[better], near[better, j], b[better]
    return tri, bary


def _barycentric(tris, points):
    """Barycentric coordinates (N, 3) of the points' projections onto triangles (N, 3, 3),
    clipped to the triangle (then renormalised)."""
    a, e1, e2 = tris[:, 0], tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]
    d = points - a
    g11, g12, g22 = (np.einsum("ij,ij->i", x, y) for x, y in ((e1, e1), (e1, e2), (e2, e2)))
    r1, r2 = np.einsum("ij,ij->i", d, e1), np.einsum("ij,ij->i", d, e2)
    det = np.where(np.abs(g11 * g22 - g12 * g12) > 1e-300, g11 * g22 - g12 * g12, 1e-300)
    u = (g22 * r1 - g12 * r2) / det
    v = (g11 * r2 - g12 * r1) / det
    b = np.clip(np.stack([1 - u - v, u, v], -1), 0.0, None)
    return b / np.maximum(b.sum(axis=1, keepdims=True), 1e-300)


def check_scene(scene) -> str | None:
    """Why the blender backend cannot render this scene's lens (one line), or None."""
    camera = scene.camera
    if not geo.has_distortion(camera):
        return None
    keyed = [n for n in ("focal_length", "shift_x", "shift_y") if camera.keyframes.get(n)]
    if keyed:
        return (f"camera {camera.name!r} has a lens and keyframed {keyed}: the lens shader "
                "bakes fixed intrinsics")
    if getattr(camera, "use_dof", False):
        return f"camera {camera.name!r} has a lens and use_dof=True: the lens camera is a pinhole"
    return None



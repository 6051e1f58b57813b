"""A CPU ray-casting renderer: the exact annotation layers from the scene model alone (no bpy).

One ray per pixel centre (:func:`kubric.core.camera_geometry.pixel_centre_rays`) is cast with Embree
(``embreex`` through trimesh; ``pip install kubric[raycast]``) into the scene's meshes posed at
the frame; Embree only finds the triangle, and the hit is then recomputed in float64 on that
triangle, so every layer is the value at the surface point seen through the pixel centre, as the
Blender backend's exact annotation render (:mod:`kubric.renderer.blender_passes`) defines it:

* ``depth``: the distance from the camera centre along the ray; ``z`` = depth converted with
  :func:`~kubric.core.camera_geometry.depth_to_z`; BACKGROUND_DEPTH (10000 m) where nothing is hit.
* ``segmentation``: the object's ``segmentation_id``, else its position in ``scene.assets`` + 1.
* ``normal``: world space, unit; flat faces: the posed triangle's normal; smooth meshes: the
  vertex normals interpolated at the hit (angle-weighted, as Blender computes them); turned to face
  the camera where the ray hits a back face (as Cycles does).
* ``object_coordinates``: the hit in the object's unscaled local frame, (p − lo) / (hi − lo) over
  the model's ``bounds``, clipped to [0, 1].
* ``uv``: the mesh's texture coordinates at the hit, wrapped into [0, 1) (0 for meshes without).
* ``forward_flow`` / ``backward_flow``: the hit point moves with its object's pose (position,
  quaternion, scale at frame t ± 1, from the model's keyframes; held outside them) and is projected
  with the camera of frame t ± 1; flow = that position − the pixel centre, as (Δrow, Δcol).
* lenses (``PerspectiveCamera.lens``, :mod:`kubric.core.lenses`): the pixel-centre rays come
  from the lens model, so RGB and every layer describe the distorted image exactly; flow projects
  the moved point through the lens too (0 where it leaves the lens's domain at t ± 1). Pixels
  outside the lens's image (no ray) are background in every layer, with rgba (0, 0, 0, 0).
* ``rgba``: NOT photoreal — base colour × (ambient + Lambert direct light from every lamp with a
  hard shadow ray) / π, Standard view transform (sRGB, clipped): enough to look at a scene and
  to make it complete against a recipe's schema; see docs/renderers.md for what it ignores.

Geometry (:mod:`kubric.renderer.raycast_meshes`): ``Cube`` and ``Sphere`` are rebuilt exactly as
the Blender backend builds them; a ``FileBasedObject``'s ``render_filename`` is read with trimesh.
A ``Deformable`` is its simulated mesh and a skinned ``Character`` its mesh skinned by the model
(``deformed_vertices``) at the frame's (or, under a rolling shutter, the row's) time; their
object coordinates and UVs are those of the material point on the rest mesh (as Blender's
``kubric_rest_position``); a character is smooth shaded, with the angle-weighted vertex normals
of the skinned mesh (as Blender recomputes them after the armature), a Deformable flat.
"""

from __future__ import annotations

import numpy as np

from kubric.core import camera_geometry as geo
from kubric.core import lights, materials, objects, rolling_shutter
from kubric.core import pbr_materials as pbr
from kubric.core.characters import Character
from kubric.core.color import Color, linear_to_srgb, srgb_to_linear
from kubric.core.deformables import DEFORMING
from kubric.core.imports import uninterrupted_import
from kubric.renderer import procedural_patterns
from kubric.renderer.base import ALL_LAYERS, PATTERN_NEED, Renderer
from kubric.renderer.raycast_meshes import (  # noqa: F401  (public names of this module)
    GREY,
    MESH_FORMATS,
    Mesh,
    cube_mesh,
    file_mesh,
    sphere_mesh,
)
from kubric.renderer.raycast_rolling import rolling_flow_ends, rolling_frame

trimesh = uninterrupted_import("trimesh")  # trimesh swallows a Ctrl-C in its import


# ---------------------------------------------------------------------------------- ray casting
def _intersect(origins, dirs, tri):
    """Möller–Trumbore in float64: (t, barycentric (b1, b2)) of rays (N, 3) with triangles
    (N, 3, 3) known to be hit (embree found them)."""
    e1, e2 = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    p = np.cross(dirs, e2)
    det = np.einsum("ij,ij->i", e1, p)
    det = np.where(np.abs(det) > 1e-300, det, 1e-300)
    s = origins - tri[:, 0]
    b1 = np.einsum("ij,ij->i", s, p) / det
    q = np.cross(s, e1)
    b2 = np.einsum("ij,ij->i", dirs, q) / det
    t = np.einsum("ij,ij->i", e2, q) / det
    return t, b1, b2


class _Geometry:
    """Every physical object's mesh joined in local coordinates (one render's worth): per vertex
    and per face the owning object ``k`` (its position in ``entries``)."""

    def __init__(self, entries):
        self.entries = entries  # [(label, asset, Mesh)]
        meshes = [e[2] for e in entries]
        counts = [len(m.vertices) for m in meshes]
        starts = np.cumsum([0] + counts)[:-1]
        self.labels = np.asarray([e[0] for e in entries], np.uint32)
        self.bounds = np.asarray([e[1].bounds for e in entries], np.float64).reshape(-1, 2, 3)
        self.vertex_owner = np.repeat(np.arange(len(meshes)), counts)
        self.vertices = _join([m.vertices for m in meshes], (0, 3))
        self.faces = _join([m.faces + s for m, s in zip(meshes, starts, strict=True)],
                           (0, 3)).astype(np.int64)
        self.face_owner = np.repeat(np.arange(len(meshes)), [len(m.faces) for m in meshes])
        self.smooth = np.asarray([m.normals is not None for m in meshes], bool)
        self.normals = _join([m.vertices * 0 if m.normals is None else m.normals
                              for m in meshes], (0, 3))
        self.corner_uv = _join([np.zeros((len(m.faces), 3, 2)) if m.corner_uv is None
                                else m.corner_uv for m in meshes], (0, 3, 2))
        # deforming surfaces (Deformables, skinned characters): (k, asset, first vertex, end) —
        # their vertices come from the model per frame; their local points are rest-state
        # model-frame points (docs/deformables.md, docs/characters.md)
        self.deforming = [(k, e[1], starts[k], starts[k] + counts[k])
                          for k, e in enumerate(entries) if isinstance(e[1], DEFORMING)]
        # characters are smooth shaded (as Blender builds them): normals of the skinned mesh
        self.skinned = [d for d in self.deforming if isinstance(d[1], Character)]
        self.smooth[[k for k, *_ in self.skinned]] = True

    def poses(self, frame):
        """(K, 3, 3) rotations, (K, 3) translations and (K, 3) scales of the objects at
        ``frame`` (the model's keyframes, held outside them)."""
        rot, trans, scale = [], [], []
        for _, asset, _ in self.entries:
            with asset.at_frame(frame):
                m = asset.matrix_world
                rot.append(m[:3, :3])
                trans.append(m[:3, 3])
                scale.append(np.asarray(asset.scale, np.float64))
        if not rot:
            return np.zeros((0, 3, 3)), np.zeros((0, 3)), np.zeros((0, 3))
        return np.stack(rot), np.stack(trans), np.stack(scale)

    def to_world(self, points, owner, poses):
        """Local points (N, 3) of objects ``owner`` (N,) → world, with ``poses``."""
        rot, trans, scale = poses
        return np.einsum("nij,nj->ni", rot[owner], points * scale[owner]) + trans[owner]

    def posed_vertices(self, frame, poses):
        """(V, 3) every vertex in the world at ``frame``: rigid objects with ``poses``,
        deformables as the model's simulated mesh of that frame."""
        world = self.to_world(self.vertices, self.vertex_owner, poses)
        for _, asset, start, end in self.deforming:
            world[start:end] = asset.deformed_vertices(frame)
        return world

    def surface_world(self, local, owner, tid, bary, frame):
        """World positions at ``frame`` of hit points (N) given as local points ``local`` (N, 3)
        of objects ``owner`` on triangles ``tid`` with barycentrics ``bary`` (N, 3): rigid
        objects move the local point with their pose, deformables follow the material point
        (the triangle's vertices at that frame)."""
        world = self.to_world(local, owner, self.poses(frame))
        for k, asset, start, _ in self.deforming:
            sel = np.flatnonzero(owner == k)
            if len(sel):
                verts = asset.deformed_vertices(frame)
                world[sel] = np.einsum("nk,nkj->nj", bary[sel],
                                       verts[self.faces[tid[sel]] - start])
        return world


def _join(arrays, empty_shape):
    return np.concatenate(arrays) if len(arrays) else np.zeros(empty_shape)


class _PosedScene:
    """The joined meshes posed at one frame, searchable by Embree."""

    def __init__(self, geometry: _Geometry, frame):
        self.poses = geometry.poses(frame)
        world = geometry.posed_vertices(frame, self.poses)
        self.mesh = trimesh.Trimesh(world, geometry.faces, process=False)
        self.triangles = world[geometry.faces]
        self._ray = None
        # (V, 3) world vertex normals of the skinned characters' meshes at this frame
        # (angle-weighted, as Blender computes them; 0 elsewhere)
        self.skinned_normals = np.zeros_like(world) if geometry.skinned else None
        for _, asset, start, end in geometry.skinned:
            mesh = trimesh.Trimesh(world[start:end], asset.faces, process=False)
            self.skinned_normals[start:end] = mesh.vertex_normals

    def first_hits(self, origins, dirs):
        """Index of the first triangle hit by each ray (−1: none)."""
        if len(self.triangles) == 0:
            return np.full(len(origins), -1)
        if self._ray is None:
            from trimesh.ray.ray_pyembree import RayMeshIntersector
            self._ray = RayMeshIntersector(self.mesh)
        return np.asarray(self._ray.intersects_first(origins, dirs), np.int64)


class Raycast(Renderer):
    """Embree ray-casting backend of the renderer protocol (see module doc).

    Settings: ``background_transparency`` (bool: rgba alpha 0 where no surface is hit; default
    False, the background colour is opaque); ``motion_blur`` only 0 / False (a recipe passes its
    shutter; this backend renders no exposure effect: a shutter, or a camera with ``use_dof``,
    is refused in one line naming the backends that render it). ``scratch_dir`` is accepted for
    the protocol and unused (nothing is written).
    """

    def __init__(self, scene, scratch_dir=None, *, background_transparency=False,
                 motion_blur=0.0):
        if not isinstance(background_transparency, (bool, np.bool_)):
            raise TypeError("Raycast option background_transparency must be True or False, got "
                            f"{background_transparency!r}")
        self.require_effects({"motion_blur": motion_blur and f"motion_blur={motion_blur!r}"})
        self.scene = scene
        self.scratch_dir = scratch_dir
        self.background_transparency = bool(background_transparency)
        self._meshes: dict = {}  # asset → Mesh, read once per renderer
        self._textures: dict = {}  # path → linear image, read once per renderer

    def settings(self) -> dict:
        return {"engine": "RAYCAST", "view_transform": "Standard",
                "rgba": "base colour x (ambient + Lambert direct light, hard shadows) / pi; "
                        "not photoreal"}

    # ------------------------------------------------------------------ scene → meshes
    def _mesh_of(self, asset) -> Mesh:
        if asset not in self._meshes:
            if isinstance(asset, objects.Cube):
                mesh = cube_mesh()
            elif isinstance(asset, objects.Sphere):
                mesh = sphere_mesh()
            elif isinstance(asset, objects.FileBasedObject):
                mesh = file_mesh(asset)
            elif isinstance(asset, DEFORMING):  # the rest mesh; posed per frame by the model
                mesh = Mesh(np.asarray(asset.vertices, np.float64),
                            np.asarray(asset.faces, np.int64), None,
                            None if asset.uv is None else np.asarray(asset.uv, np.float64))
            else:
                raise ValueError(f"{asset.uid}: the raycast renderer has no geometry for "
                                 f"{type(asset).__name__} (Cube, Sphere, FileBasedObject, "
                                 "Deformable, Character)")
            self._meshes[asset] = mesh
        return self._meshes[asset]

    def geometry(self) -> _Geometry:
        """Every physical object's mesh, labelled as the Blender backend labels them
        (segmentation_id, else position in scene.assets + 1)."""
        entries = []
        for i, asset in enumerate(self.scene.assets, start=1):
            if isinstance(asset, objects.PhysicalObject):
                seg = asset.segmentation_id
                entries.append((i if seg is None else int(seg), asset, self._mesh_of(asset)))
        return _Geometry(entries)

    # ------------------------------------------------------------------ rendering
    def render(self, frames=None, return_layers=ALL_LAYERS) -> dict[str, np.ndarray]:
        """Render ``frames`` → {layer: (T, H, W, C) array} (see module doc)."""
        frames, wanted = self.check_request(frames, return_layers)
        camera = self.scene.camera
        if camera is None:
            raise ValueError("the scene has no camera: add a PerspectiveCamera or "
                             "OrthographicCamera before rendering")
        self.require_effects({"depth_of_field": getattr(camera, "use_dof", False) and
                              f"camera {camera.name!r} use_dof=True"})
        geometry = self.geometry()
        if "rgba" in wanted:
            self.require_patterns(geometry)
        out: dict[str, np.ndarray] = {}
        rolling = rolling_shutter.duration_of(camera) > 0
        for i, frame in enumerate(frames):
            layers = (rolling_frame(self, camera, geometry, frame, wanted) if rolling else
                      self.render_frame(camera, geometry, frame, wanted))
            for name in wanted:
                if name not in out:
                    out[name] = np.empty((len(frames),) + layers[name].shape, layers[name].dtype)
                out[name][i] = layers[name]
        return out

    def render_frame(self, camera, geometry, frame, wanted, rows=None,
                     rolling_from=None) -> dict[str, np.ndarray]:
        """One frame's layers ``wanted`` → {layer: (H, W, C)} at time ``frame`` (fractional
        allowed). Rolling shutter (:mod:`kubric.renderer.raycast_rolling`): ``rows`` casts only
        these image rows' rays (the others read as background), and ``rolling_from`` (a frame
        number) makes the flows end at the rolling-shutter positions in frame
        ``rolling_from ± 1``."""
        w, h = self.scene.resolution
        centres = geo.pixel_centres(h, w).reshape(-1, 2)
        origins, dirs = geo.pixel_centre_rays(camera, frame=frame, resolution=(w, h))
        posed = _PosedScene(geometry, frame)
        has_ray = np.isfinite(dirs).all(axis=1)  # a lens's image may not fill the frame
        if rows is not None:
            has_ray &= np.isin(np.arange(h * w) // w, rows)
        tri_id = np.full(len(dirs), -1, np.int64)
        tri_id[has_ray] = posed.first_hits(origins[has_ray], dirs[has_ray])
        hit = tri_id >= 0
        idx = np.flatnonzero(hit)
        tid = tri_id[idx]
        t, b1, b2 = _intersect(origins[idx], dirs[idx], posed.triangles[tid])
        owner = geometry.face_owner[tid]
        bary = np.stack([1 - b1 - b2, b1, b2], -1)
        corners = geometry.faces[tid]
        local = np.einsum("nk,nkj->nj", bary, geometry.vertices[corners])
        uv = np.einsum("nk,nkj->nj", bary, geometry.corner_uv[tid])
        res: dict[str, np.ndarray] = {}

        def image(values, channels, dtype=np.float32, fill=0.0):
            img = np.full((h * w, channels), fill, dtype)
            img[idx] = np.asarray(values).reshape(len(idx), channels)
            return img.reshape(h, w, channels)

        depth = image(t, 1, np.float64, geo.BACKGROUND_DEPTH)
        res["depth"] = depth.astype(np.float32)
        mask = hit.reshape(h, w, 1)
        res["z"] = np.where(mask, geo.depth_to_z(camera, np.where(mask, depth, 0.0)),
                            geo.BACKGROUND_DEPTH).astype(np.float32)
        res["segmentation"] = image(geometry.labels[owner], 1, np.uint32, 0)
        normals = self._normals(geometry, posed, tid, owner, bary, dirs[idx])
        res["normal"] = image(normals, 3)
        lo, hi = geometry.bounds[owner, 0], geometry.bounds[owner, 1]
        extent = np.where(hi - lo > 0, hi - lo, 1.0)
        generated = np.clip((local - lo) / extent, 0, 1)
        res["object_coordinates"] = image(generated, 3)
        res["uv"] = image(np.concatenate([np.mod(uv, 1.0), np.zeros((len(idx), 1))], 1), 3)
        for name, step in (("forward_flow", 1), ("backward_flow", -1)):
            if name in wanted:
                if rolling_from is not None:
                    xy = rolling_flow_ends(camera, geometry, (local, owner, tid, bary),
                                           rolling_from + step, (w, h))
                else:
                    world = geometry.surface_world(local, owner, tid, bary, frame + step)
                    xy, _ = geo.project_to_pixels(camera, world, frame=frame + step,
                                                  resolution=(w, h))
                flow = xy[:, ::-1] - centres[idx, ::-1]  # (Δrow, Δcol)
                res[name] = image(np.nan_to_num(flow, nan=0.0), 2)  # NaN: left the lens's domain
        if "rgba" in wanted:
            points = origins[idx] + dirs[idx] * t[:, None]
            res["rgba"] = self._shade(geometry, posed, owner, (uv, generated), points, normals,
                                      frame, hit, (h, w))
            res["rgba"][~has_ray.reshape(h, w)] = 0  # outside the lens's image: no light
        return {k: res[k] for k in wanted}

    def require_patterns(self, geometry) -> None:
        """One line (CapabilityError) for a ProceduralMaterial whose pattern this backend's RGB
        does not show (:mod:`kubric.renderer.procedural_patterns`)."""
        for _, asset, _ in geometry.entries:
            material = asset.material
            if isinstance(material, pbr.ProceduralMaterial):
                self._require({PATTERN_NEED + material.pattern:
                               f"{asset.uid}'s material pattern={material.pattern}"},
                              "Raycast.render")

    @staticmethod
    def _normals(geometry, posed, tid, owner, bary, dirs):
        """World unit normals at the hits, facing the camera."""
        tri = posed.triangles[tid]
        geometric = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        rot, _, scale = posed.poses
        smooth_local = np.einsum("nk,nkj->nj", bary, geometry.normals[geometry.faces[tid]])
        # normals transform with the inverse scale
        smooth = np.einsum("nij,nj->ni", rot[owner], smooth_local / scale[owner])
        if posed.skinned_normals is not None:  # skinned: the posed mesh's own vertex normals
            sk = np.flatnonzero(np.isin(owner, [k for k, *_ in geometry.skinned]))
            smooth[sk] = np.einsum("nk,nkj->nj", bary[sk],
                                   posed.skinned_normals[geometry.faces[tid[sk]]])
        normals = np.where(geometry.smooth[owner][:, None], smooth, geometric)
        normals /= np.linalg.norm(normals, axis=1, keepdims=True)
        back = np.einsum("ij,ij->i", geometric, dirs) > 0
        return np.where(back[:, None], -normals, normals)

    # ------------------------------------------------------------------ rgba
    def _albedo(self, asset, mesh, uv, generated):
        """Linear base colour (N, 3) of ``asset``'s hits with texture coordinates ``uv`` and
        generated coordinates ``generated`` (procedural materials)."""
        material = asset.material
        if isinstance(material, pbr.ProceduralMaterial):
            return procedural_patterns.base_color(material, generated)
        if isinstance(material, pbr.ImageMaterial):
            image = _load_texture(material.base_color, self._textures)
            return _sample(image, uv * float(material.uv_scale))
        color = getattr(material, "color", None)
        if isinstance(material, materials.UndefinedMaterial):
            if mesh.texture is not None:
                return _sample(mesh.texture, uv)
            return np.broadcast_to(np.asarray(mesh.color[:3], np.float64), (len(uv), 3))
        if isinstance(color, Color):
            return np.broadcast_to(np.asarray(color.rgb, np.float64), (len(uv), 3))
        if isinstance(color, materials.Texture) and color.mapping == "uv" and color.filename:
            return _sample(_load_texture(color.filename, self._textures), uv) * color.strength
        if isinstance(color, materials.Texture) and color.filename:  # environment-mapped
            return np.broadcast_to(_ambient_radiance(color, self._textures), (len(uv), 3))
        return np.broadcast_to(np.asarray(GREY), (len(uv), 3))

    def _shade(self, geometry, posed, owner, coords, points, normals, frame, hit, hw):
        h, w = hw
        uv, generated = coords
        ambient = _ambient_radiance(self.scene.ambient_illumination, self._textures)
        irradiance = np.broadcast_to(np.pi * ambient, (len(points), 3)).copy()
        eps = 1e-4 * max(1.0, float(np.abs(posed.triangles).max())) if len(points) else 0.0
        start = points + normals * eps
        for light in self.scene.assets:
            if isinstance(light, lights.Light) and not isinstance(light, lights.UndefinedLight):
                irradiance += _irradiance(light, posed, start, normals, frame)
        radiance = np.zeros((len(points), 3))
        for k, (_, asset, mesh) in enumerate(geometry.entries):
            sel = np.flatnonzero(owner == k)
            if len(sel):
                albedo = self._albedo(asset, mesh, uv[sel], generated[sel])
                unlit = isinstance(asset.material, materials.FlatMaterial)
                radiance[sel] = albedo if unlit else albedo * irradiance[sel] / np.pi
        rgba = np.zeros((h * w, 4), np.uint8)
        background = self.scene.background
        if isinstance(background, Color) and not self.background_transparency:
            rgba[:, :3] = np.round(linear_to_srgb(background.rgb) * 255)
            rgba[:, 3] = 255
        rgba[hit, :3] = np.round(linear_to_srgb(radiance) * 255)
        rgba[hit, 3] = 255
        return rgba.reshape(h, w, 4)


def _irradiance(light, posed, start, normals, frame):
    """Irradiance (N, 3) at ``start`` from one lamp, with a hard shadow ray per point."""
    with light.at_frame(frame):
        m = light.matrix_world
        color = np.asarray(light.color.rgb) * float(light.intensity)
        axis = -m[:3, 2]  # lights shine along local −z
        if isinstance(light, lights.DirectionalLight):
            to_light = np.broadcast_to(-axis, start.shape)
            dist = np.full(len(start), np.inf)
            falloff = np.ones(len(start))
        else:
            vec = m[:3, 3] - start
            dist = np.linalg.norm(vec, axis=1)
            to_light = vec / np.maximum(dist, 1e-12)[:, None]
            falloff = 1.0 / (4 * np.pi * np.maximum(dist, 1e-6) ** 2)
            if isinstance(light, lights.SpotLight):
                cos = np.einsum("ij,j->i", -to_light, axis)
                half = np.cos(float(light.spot_size) / 2)
                blend = max(float(light.spot_blend) * (1 - half), 1e-9)
                falloff = falloff * np.clip((cos - half) / blend, 0, 1)
            elif isinstance(light, lights.RectAreaLight):
                falloff = falloff * 4 * np.clip(np.einsum("ij,j->i", -to_light, axis), 0, 1)
    cos = np.clip(np.einsum("ij,ij->i", normals, to_light), 0, None)
    lit = np.flatnonzero(cos * falloff > 0)
    if len(lit):
        blocker = posed.first_hits(start[lit], np.ascontiguousarray(to_light[lit]))
        blocked = blocker >= 0
        if blocked.any():
            b = lit[blocked]
            t, _, _ = _intersect(start[b], to_light[b], posed.triangles[blocker[blocked]])
            cos[b[(t > 0) & (t < dist[b])]] = 0.0
    return (cos * falloff)[:, None] * color


def _ambient_radiance(ambient, cache) -> np.ndarray:
    """(3,) radiance of the light from all directions: a Color, or an environment Texture's mean
    over the sphere (equirectangular rows weighted by cos(latitude)) × its strength."""
    if isinstance(ambient, Color):
        return np.asarray(ambient.rgb, np.float64)
    image = _load_texture(ambient.filename, cache)
    rows = image.shape[0]
    weight = np.cos((np.arange(rows) + 0.5) / rows * np.pi - np.pi / 2)
    mean = np.einsum("r,rc->c", weight, image.mean(axis=1)) / weight.sum()
    return mean * float(ambient.strength)


def _load_texture(path: str, cache: dict) -> np.ndarray:
    """A texture file as a linear (h, w, 3) float image (kept in ``cache`` by path): OpenEXR
    files as stored (linear), other images through PIL, sRGB-decoded."""
    if path not in cache:
        if path.lower().endswith(".exr"):
            import OpenEXR
            with OpenEXR.File(path) as f:
                channels = f.channels()
                rgb = channels["RGB"].pixels if "RGB" in channels else np.stack(
                    [channels[c].pixels for c in "RGB"], -1)
            cache[path] = np.asarray(rgb, np.float64)[..., :3]
        else:
            from PIL import Image
            with Image.open(path) as im:
                pixels = np.asarray(im.convert("RGB"), np.float64) / 255.0
            cache[path] = srgb_to_linear(pixels)
    return cache[path]


def _sample(image, uv):
    """Nearest-texel lookup of (N, 2) texture coordinates (repeating; v up, as Blender)."""
    th, tw = image.shape[:2]
    u, v = np.mod(uv[:, 0], 1.0), np.mod(uv[:, 1], 1.0)
    cols = np.minimum((u * tw).astype(int), tw - 1)
    rows = np.minimum(((1 - v) * th).astype(int), th - 1)
    return image[rows, cols]

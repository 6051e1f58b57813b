"""A real textured GLB written byte by byte (glTF 2.0 JSON chunk + binary chunk + PNG images),
independent of trimesh and of the converter: four parts, each with its own PBR material.

Parts (z up, metres; glTF stores (x, y, z) as (x, z, -y)); every front face lies in the plane
y = FRONT_Y and faces -y:

* ``A`` box: base-colour texture (left half of u red, right half blue), metallic 0, roughness
  1, a (flat) normal map;
* ``B`` box: white, a metallic-roughness texture giving metallic 1, roughness 0.05 (a mirror);
* ``D`` box: white, a metallic-roughness texture giving metallic 0, roughness 1 (matte);
* ``C`` quad: green texture whose left half (u < 0.5) has alpha 0, ``alphaMode`` MASK,
  ``alphaCutoff`` 0.5, double sided.
"""

from __future__ import annotations

import io
import json
import struct
from pathlib import Path

import numpy as np

FRONT_Y = -0.25
#: part → (x min, x max, z min, z max) of its front face
PARTS = {"A": (-1.6, -1.0, 0.0, 0.6), "B": (-0.8, -0.2, 0.0, 0.6),
         "D": (0.0, 0.6, 0.0, 0.6), "C": (0.8, 1.4, 0.0, 0.6)}
RED, BLUE, GREEN = (220, 20, 20), (20, 20, 220), (30, 200, 30)


def png_bytes(rgba: np.ndarray) -> bytes:
    from PIL import Image

    buf = io.BytesIO()
    Image.fromarray(np.asarray(rgba, np.uint8)).save(buf, format="PNG")
    return buf.getvalue()


def _images() -> dict[str, bytes]:
    size = 8
    colour = np.zeros((size, size, 4), np.uint8)
    colour[..., 3] = 255
    colour[:, : size // 2, :3] = RED
    colour[:, size // 2:, :3] = BLUE
    normal = np.zeros((size, size, 3), np.uint8)
    normal[:] = (128, 128, 255)
    mirror = np.zeros((size, size, 3), np.uint8)
    mirror[:] = (255, 13, 255)       # R: occlusion 1, G: roughness 0.05, B: metallic 1
    matte = np.zeros((size, size, 3), np.uint8)
    matte[:] = (255, 255, 0)         # roughness 1, metallic 0
    masked = np.zeros((size, size, 4), np.uint8)
    masked[..., :3] = GREEN
    masked[:, size // 2:, 3] = 255   # u < 0.5 transparent
    return {"colour": png_bytes(colour), "normal": png_bytes(normal),
            "mirror": png_bytes(mirror), "matte": png_bytes(matte), "masked": png_bytes(masked)}


def _box(x0, x1, z0, z1, depth=0.5):
    """24 vertices (z up), UVs with u along +x on the front face, v down (glTF), 12 triangles."""
    y0, y1 = FRONT_Y, FRONT_Y + depth
    faces = [  # four corners counter-clockwise seen from outside; first = (u 0, v 1)
        [(x0, y0, z0), (x1, y0, z0), (x1, y0, z1), (x0, y0, z1)],   # front (-y)
        [(x1, y1, z0), (x0, y1, z0), (x0, y1, z1), (x1, y1, z1)],   # back
        [(x1, y0, z0), (x1, y1, z0), (x1, y1, z1), (x1, y0, z1)],   # +x
        [(x0, y1, z0), (x0, y0, z0), (x0, y0, z1), (x0, y1, z1)],   # -x
        [(x0, y0, z1), (x1, y0, z1), (x1, y1, z1), (x0, y1, z1)],   # top
        [(x0, y1, z0), (x1, y1, z0), (x1, y0, z0), (x0, y0, z0)],   # bottom
    ]
    return _quads(faces)


def _quads(faces):
    verts, uvs, tris = [], [], []
    for k, corners in enumerate(faces):
        verts += corners
        uvs += [(0, 1), (1, 1), (1, 0), (0, 0)]
        tris += [(4 * k, 4 * k + 1, 4 * k + 2), (4 * k, 4 * k + 2, 4 * k + 3)]
    return np.asarray(verts, np.float32), np.asarray(uvs, np.float32), np.asarray(tris, np.uint16)


def _to_gltf(v):
    return np.stack([v[:, 0], v[:, 2], -v[:, 1]], axis=1).astype(np.float32)


#: Sketchfab's root node: its children's vertices are z up, the node turns them y up
SKETCHFAB_ROOT = [1, 0, 0, 0, 0, 0, -1, 0, 0, 1, 0, 0, 0, 0, 0, 1]  # column-major 4 x 4


def textured_glb(path: Path, scale: float = 1.0, sketchfab_root: bool = False) -> Path:
    """Write the four-part GLB described in the module doc (every length times ``scale``);
    with ``sketchfab_root`` the vertices are stored z up under a root node whose matrix turns
    them y up (as Sketchfab's exports do), the same model once transformed. Returns ``path``."""
    images = _images()
    order = list(images)
    geometry = {name: _box(*PARTS[name]) for name in "ABD"}
    x0, x1, z0, z1 = PARTS["C"]
    geometry["C"] = _quads([[(x0, FRONT_Y, z0), (x1, FRONT_Y, z0), (x1, FRONT_Y, z1),
                             (x0, FRONT_Y, z1)]])
    geometry = {k: (v * np.float32(scale), uv, t) for k, (v, uv, t) in geometry.items()}
    blob, views, accessors = bytearray(), [], []

    def add(data: bytes, target=None) -> int:
        while len(blob) % 4:
            blob.append(0)
        view = {"buffer": 0, "byteOffset": len(blob), "byteLength": len(data)}
        if target:
            view["target"] = target
        blob.extend(data)
        views.append(view)
        return len(views) - 1

    def accessor(array, kind, ctype, target, minmax=False) -> int:
        acc = {"bufferView": add(array.tobytes(), target), "componentType": ctype,
               "count": int(len(array)), "type": kind}
        if minmax:
            acc["min"], acc["max"] = array.min(0).tolist(), array.max(0).tolist()
        accessors.append(acc)
        return len(accessors) - 1

    meshes, nodes = [], []
    material_of = {"A": 0, "B": 1, "D": 2, "C": 3}
    for name in "ABDC":
        verts, uvs, tris = geometry[name]
        prim = {"attributes": {
            "POSITION": accessor(verts if sketchfab_root else _to_gltf(verts), "VEC3", 5126,
                                 34962, minmax=True),
            "TEXCOORD_0": accessor(uvs, "VEC2", 5126, 34962)},
            "indices": accessor(tris.reshape(-1), "SCALAR", 5123, 34963),
            "material": material_of[name]}
        meshes.append({"name": name, "primitives": [prim]})
        nodes.append({"name": name, "mesh": len(meshes) - 1})
    image_views = [add(images[k]) for k in order]
    tex = {k: i for i, k in enumerate(order)}
    materials = [
        {"name": "textured", "pbrMetallicRoughness": {
            "baseColorTexture": {"index": tex["colour"]}, "metallicFactor": 0.0,
            "roughnessFactor": 1.0}, "normalTexture": {"index": tex["normal"]}},
        {"name": "mirror", "pbrMetallicRoughness": {
            "baseColorFactor": [1, 1, 1, 1], "metallicRoughnessTexture": {"index": tex["mirror"]}}},
        {"name": "matte", "pbrMetallicRoughness": {
            "baseColorFactor": [1, 1, 1, 1], "metallicRoughnessTexture": {"index": tex["matte"]}}},
        {"name": "masked", "pbrMetallicRoughness": {
            "baseColorTexture": {"index": tex["masked"]}, "metallicFactor": 0.0},
         "alphaMode": "MASK", "alphaCutoff": 0.5, "doubleSided": True},
    ]
    roots = list(range(len(nodes)))
    if sketchfab_root:
        nodes.append({"name": "Sketchfab_model", "matrix": SKETCHFAB_ROOT, "children": roots})
        roots = [len(nodes) - 1]
    doc = {"asset": {"version": "2.0", "generator": "kubric tests (hand-written)"},
           "scene": 0, "scenes": [{"nodes": roots}], "nodes": nodes,
           "meshes": meshes, "materials": materials, "accessors": accessors,
           "bufferViews": views, "buffers": [{"byteLength": 0}],
           "samplers": [{"magFilter": 9728, "minFilter": 9728}],
           "textures": [{"source": i, "sampler": 0} for i in range(len(order))],
           "images": [{"bufferView": v, "mimeType": "image/png"} for v in image_views]}
    while len(blob) % 4:
        blob.append(0)
    doc["buffers"][0]["byteLength"] = len(blob)
    text = json.dumps(doc).encode()
    text += b" " * (-len(text) % 4)
    body = struct.pack("<II", len(text), 0x4E4F534A) + text + \
        struct.pack("<II", len(blob), 0x004E4942) + bytes(blob)
    path = Path(path)
    path.write_bytes(b"glTF" + struct.pack("<II", 2, 12 + len(body)) + body)
    return path

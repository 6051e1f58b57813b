"""GLB files of z-up meshes: glTF is y-up, so a mesh in Kubric's frame (z up, metres) is written
rotated by (x, y, z) → (x, z, −y), and a glTF importer (Blender's, trimesh's) turns it back."""

from __future__ import annotations

from pathlib import Path

import numpy as np

#: Kubric's z-up frame → glTF's y-up frame (homogeneous 4 × 4)
Z_UP_TO_GLTF = np.array([[1, 0, 0, 0], [0, 0, 1, 0], [0, -1, 0, 0], [0, 0, 0, 1]], dtype=float)


def write_visual_glb(mesh, path: Path) -> None:
    """Write the trimesh ``mesh`` (z up) to ``path`` as a GLB in glTF's y-up convention; a list
    of trimeshes becomes one primitive (with its own material) each."""
    if isinstance(mesh, (list, tuple)):
        import trimesh

        scene = trimesh.Scene()
        for k, part in enumerate(mesh):
            m = part.copy()
            m.apply_transform(Z_UP_TO_GLTF)
            scene.add_geometry(m, geom_name=f"part_{k:03d}")
        Path(path).write_bytes(scene.export(file_type="glb"))
        return
    m = mesh.copy()
    m.apply_transform(Z_UP_TO_GLTF)
    Path(path).write_bytes(m.export(file_type="glb"))

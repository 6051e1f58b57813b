"""Shared checks for the asset tests: a PyBullet drop test and a Blender import of an asset.

(Helpers only; the tests that use them live in test_assets_kubasic.py and test_assets_convert.py.)
"""

from __future__ import annotations

import numpy as np


def drop_test(urdf: str, bounds, mass: float, seconds: float = 10.0) -> dict:
    """Drop the URDF onto pybullet_data's plane from a small height; simulate until it has been
    still for 0.5 s (at most ``seconds``); return the final state.

    Returns {"mass": engine mass, "speed": |v| (m/s), "spin": |ω| (rad/s), "aabb": (2, 3),
    "size": largest extent of ``bounds``, "t": simulated seconds}.
    """
    import os

    import pybullet as pb
    import pybullet_data

    bounds = np.asarray(bounds, dtype=np.float64)
    hull_file = os.path.join(os.path.dirname(urdf), "collision_geometry.obj")
    with open(hull_file) as fh:
        verts = np.array([[float(x) for x in line.split()[1:4]] for line in fh
                          if line.startswith("v ")])
    size = float((bounds[1] - bounds[0]).max())
    client = pb.connect(pb.DIRECT)
    try:
        pb.setGravity(0, 0, -10, physicsClientId=client)
        pb.loadURDF(f"{pybullet_data.getDataPath()}/plane.urdf", physicsClientId=client)
        z0 = -bounds[0, 2] + 0.1 * size
        body = pb.loadURDF(urdf, basePosition=(0, 0, z0), physicsClientId=client)
        engine_mass = pb.getDynamicsInfo(body, -1, physicsClientId=client)[0]
        still, step = 0, 0
        while step < seconds * 240 and still < 120:
            pb.stepSimulation(physicsClientId=client)
            step += 1
            lin, ang = pb.getBaseVelocity(body, physicsClientId=client)
            slow = np.linalg.norm(lin) < 0.01 * max(size, 0.05) and np.linalg.norm(ang) < 0.2
            still = still + 1 if step > 240 and slow else 0
        pos, orn = pb.getBasePositionAndOrientation(body, physicsClientId=client)
        rot = np.asarray(pb.getMatrixFromQuaternion(orn)).reshape(3, 3)
    finally:
        pb.disconnect(client)
    world = verts @ rot.T + np.asarray(pos)
    aabb = np.stack([world.min(axis=0), world.max(axis=0)])  # of the collision hull vertices
    return {"mass": engine_mass, "speed": float(np.linalg.norm(lin)),
            "spin": float(np.linalg.norm(ang)), "aabb": aabb, "size": size, "t": step / 240}


def assert_rests_on_floor(state: dict, mass: float) -> None:
    size = state["size"]
    assert state["mass"] == __import__("pytest").approx(mass, rel=1e-5)
    assert state["speed"] < 0.01 * max(size, 0.05), state
    assert state["spin"] < 0.2, state
    # resting on the plane: neither sunk through it nor floating above it
    assert -0.02 * size - 0.005 < state["aabb"][0, 2] < 0.05 * size + 0.005, state


def blender_import_bounds(path: str, import_kwargs: dict) -> np.ndarray:
    """Import a mesh file into an empty Blender scene; return its world-space (2, 3) bounds."""
    import bpy

    bpy.ops.wm.read_factory_settings(use_empty=True)
    if path.endswith((".glb", ".gltf")):
        bpy.ops.import_scene.gltf(filepath=path, **import_kwargs)
    else:
        bpy.ops.wm.obj_import(filepath=path, **import_kwargs)
    pts = []
    for obj in bpy.context.scene.objects:
        if obj.type != "MESH":
            continue
        mw = np.array(obj.matrix_world)
        co = np.array([v.co[:] for v in obj.data.vertices], dtype=np.float64)
        pts.append(co @ mw[:3, :3].T + mw[:3, 3])
    assert pts, f"no mesh imported from {path}"
    pts = np.concatenate(pts)
    return np.stack([pts.min(axis=0), pts.max(axis=0)])


def blender_silhouette(path: str, import_kwargs: dict, ortho_scale: float, res: int = 32):
    """Render the imported mesh from the front (camera at −y looking +y, orthographic) with Cycles
    at 1 sample on a transparent film; return the (res, res) boolean coverage mask (row 0 = top).
    """
    import os
    import tempfile

    import bpy

    blender_import_bounds(path, import_kwargs)
    scene = bpy.context.scene
    cam_data = bpy.data.cameras.new("cam")
    cam_data.type = "ORTHO"
    cam_data.ortho_scale = ortho_scale
    cam_data.clip_end = 10 * ortho_scale
    cam = bpy.data.objects.new("cam", cam_data)
    cam.location = (0.0, -4.0 * ortho_scale, 0.0)
    cam.rotation_euler = (np.pi / 2, 0.0, 0.0)
    scene.collection.objects.link(cam)
    scene.camera = cam
    scene.render.engine = "CYCLES"
    scene.cycles.samples = 1
    scene.cycles.use_denoising = False
    scene.cycles.use_adaptive_sampling = False
    scene.cycles.filter_width = 0.01
    scene.render.resolution_x = scene.render.resolution_y = res
    scene.render.resolution_percentage = 100
    scene.render.film_transparent = True
    scene.render.image_settings.file_format = "PNG"
    scene.render.image_settings.color_mode = "RGBA"
    with tempfile.TemporaryDirectory() as tmp:
        out = os.path.join(tmp, "s.png")
        scene.render.filepath = out
        bpy.ops.render.render(write_still=True)
        from PIL import Image
        alpha = np.asarray(Image.open(out))[..., 3]
    return alpha > 127

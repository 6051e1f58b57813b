"""Rolling shutter in the Blender backend: Cycles reads the RGB rows over time, the exact layers
come from the raycast backend's rolling render (docs/conventions.md, "Time inside a frame").

Cycles (``scene.cycles.rolling_shutter_type = 'TOP'``) gives every camera ray of image row y
(counted from the **bottom**, 0 … H − 1) the shutter time ``1 − y / H`` (0 = shutter open,
1 = shutter closed) when ``scene.cycles.rolling_shutter_duration`` (its scanline exposure, a
fraction of the shutter) is 0; the shutter is ``render.motion_blur_shutter`` frames centred on the
scene's current time (``motion_blur_position = 'CENTER'``). With the shutter set to the readout
time d, row r counted from the top is read at ``c + d · ((r + 1) / H − 1/2)`` for current time
c: our ``t(r + 0.5)`` plus half a row, ``d / (2H)`` frames (Cycles times the whole row by its
lower edge, not its centre). So each RGB frame f is rendered as a still at the sub-frame
``c = f − d / (2H)`` (``frame_set(⌊c⌋, subframe=c − ⌊c⌋)``, :func:`render_stills`): row r is then
read at exactly ``t(r + 0.5)``. Measured (tests/test_blender_rolling_shutter.py: a bar moving
17.5 px/frame, 48 × 16 px, d = 1, per-row intensity centre in linear RGB against the bar's
pinhole projection at the row time): uncompensated, Cycles' rows are read 0.0312 frames late
(d / (2H) = 0.03125; 0.55 px here); compensated, −0.002 frames (−0.04 px: Monte Carlo noise).

The objects and the camera move between Cycles' motion steps (3 per object: shutter open, the
current time, shutter close) by linear interpolation of their keyed transforms and of deforming
meshes' vertices (a skinned character's armature is evaluated at each step): the scene model's
motion where it is linear over the shutter (rigid keys at whole frames: exact but for the
d / (2H) around a key that the compensation moves into a step's span; rotations: slerp of the
decomposed transforms; skinned limbs: vertices linear between the steps, the model's skinning
only at the steps).

The exact layers (depth, segmentation, flow, …) are the raycast backend's, rendered with the same
rolling shutter (:mod:`kubric.renderer.raycast_rolling`; skinned characters and Deformables
cast per row with their mesh at the row's time). A rolling shutter together with motion blur
(Cycles would blend the two in a way that is not our convention) or depth of field (the raycast
layers have no thin lens to match) is refused in one line.
"""

from __future__ import annotations

import math

from kubric.core.rolling_shutter import duration_of
from kubric.renderer.base import CapabilityError


def configure_cycles(bpy_scene, camera) -> None:
    """Cycles' rolling shutter for RGB from ``camera``'s ``rolling_shutter_duration`` (module
    doc); duration 0 turns it off (the motion-blur settings are then the caller's)."""
    duration = duration_of(camera)
    c = bpy_scene.cycles
    if duration <= 0:
        c.rolling_shutter_type = "NONE"
        return
    r = bpy_scene.render
    r.use_motion_blur = True
    r.motion_blur_shutter = duration
    r.motion_blur_position = "CENTER"
    c.rolling_shutter_type = "TOP"
    c.rolling_shutter_duration = 0.0  # no scanline exposure: each row one instant


def row_lead(scene) -> float:
    """How much earlier (frames) than the frame time Cycles must render for its rows to be read
    at our row times: d / (2H) (module doc)."""
    return duration_of(scene.camera) / (2.0 * scene.resolution[1])


def render_stills(bpy_scene, scene, frames, path_of) -> None:
    """Render the RGB of each of ``frames`` as a still at the sub-frame ``f − d / (2H)`` (module
    doc) to the file ``path_of(f)``; the scene's current frame is restored afterwards."""
    import bpy
    lead = row_lead(scene)
    current = bpy_scene.frame_current, bpy_scene.frame_subframe
    try:
        for f in frames:
            whole = math.floor(f - lead)
            bpy_scene.frame_set(whole, subframe=f - lead - whole)
            bpy_scene.render.filepath = str(path_of(f))
            bpy.ops.render.render(write_still=True)
    finally:
        bpy_scene.frame_set(current[0], subframe=current[1])


def check(scene, motion_blur) -> None:
    """One line (CapabilityError) where the hybrid cannot render ``scene`` (module doc)."""
    duration = duration_of(scene.camera)
    if motion_blur:
        raise CapabilityError(f"renderer=blender cannot render motion_blur={motion_blur!r} with "
                              f"a rolling shutter (rolling_shutter_duration={duration!r}); "
                              "allowed: one of the two")
    if getattr(scene.camera, "use_dof", False):
        raise CapabilityError(f"renderer=blender cannot render depth of field (use_dof=True) "
                              f"with a rolling shutter (rolling_shutter_duration={duration!r}); "
                              "allowed: one of the two")


def exact_layers(scene, frames, layers) -> dict:
    """{layer: (T, H, W, C)} of the exact ``layers`` under the rolling shutter, from the raycast
    backend (labels as the Blender backend's)."""
    from kubric.renderer.raycast import Raycast
    return Raycast(scene).render(frames=frames, return_layers=tuple(layers))

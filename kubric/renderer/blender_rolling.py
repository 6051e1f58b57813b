"""Rolling shutter in the Blender backend: Cycles reads the RGB rows over time, the exact layers
come from the raycast backend's rolling render (docs/conventions.md, "Time inside a frame").

Cycles (``scene.cycles.rolling_shutter_type = 'TOP'``) gives every camera ray of image row y
(counted from the **bottom**, 0 … H − 1) the shutter time ``1 − y / H`` (0 = shutter open,
1 = shutter closed) when ``scene.cycles.rolling_shutter_duration`` (its scanline exposure, a
fraction of the shutter) is 0; the shutter is ``render.motion_blur_shutter`` frames centred on the
frame (``motion_blur_position = 'CENTER'``). With the shutter set to the readout time d, row r
counted from the top is read at ``f + d · ((r + 1) / H − 1/2)``: our ``t(r + 0.5)`` plus half a
row, ``d / (2H)`` frames (Cycles times the whole row by its lower edge, not its centre). The
objects and the camera move between Cycles' motion steps (3 per object: shutter open, frame,
shutter close) by linear interpolation of their keyed transforms and of deforming meshes'
vertices, which is the scene model's interpolation where the keys are at whole frames and
d ≤ 2 (rotations: slerp of the decomposed transforms).

The exact layers (depth, segmentation, flow, …) are the raycast backend's, rendered with the same
rolling shutter (:mod:`kubric.renderer.raycast_rolling`); a scene the raycast backend cannot cast
(a skinned character) is refused in one line, as is a rolling shutter together with motion blur
(Cycles would blend the two in a way that is not our convention) or depth of field (the raycast
layers have no thin lens to match).
"""

from __future__ import annotations

from kubric.core.characters import Character
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
    for asset in scene.assets:
        if isinstance(asset, Character):
            raise CapabilityError(f"renderer=blender cannot render character {asset.uid!r} under "
                                  f"a rolling shutter (rolling_shutter_duration={duration!r}): "
                                  "its exact layers come from the raycast backend, which casts "
                                  "rigid objects and Deformables only")


def exact_layers(scene, frames, layers) -> dict:
    """{layer: (T, H, W, C)} of the exact ``layers`` under the rolling shutter, from the raycast
    backend (labels as the Blender backend's)."""
    from kubric.renderer.raycast import Raycast
    return Raycast(scene).render(frames=frames, return_layers=tuple(layers))

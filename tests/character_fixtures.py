"""Shared helpers for the character tests: a tiny animated scene with the procedural person."""

import numpy as np

import kubric as kb
from kubric.assets.procedural_character import tube_person, walk_clip

RES = 64


def pixel_centres(w, h):
    c, r = np.meshgrid(np.arange(w) + 0.5, np.arange(h) + 0.5)
    return np.stack([c, r], -1)


def walking_scene(frames=4, moving_camera=True, character=None, clip=None):
    """A person walking towards a camera that also moves; a floor behind. Frames 1..frames."""
    scene = kb.Scene(resolution=(RES, RES), frame_start=1, frame_end=frames, frame_rate=12)
    person = character or tube_person(position=(0.2, 0.3, 0.0), euler=(0, 0, 0.5), scale=1.05)
    scene += person
    scene += kb.Cube(name="floor", position=(0, 0, -0.05), scale=(4, 4, 0.05), static=True,
                     background=True)
    cam = kb.PerspectiveCamera(position=(1.2, -3.2, 1.3), focal_length=40)
    scene += cam
    for f in range(1, frames + 1):
        if moving_camera:
            cam.position = (1.2 - 0.1 * f, -3.2 + 0.05 * f, 1.3 + 0.03 * f)
        cam.look_at((0.1, 0.0, 0.9))
        cam.keyframe_insert("position", f)
        cam.keyframe_insert("quaternion", f)
    person.play(clip or walk_clip())
    return scene, person

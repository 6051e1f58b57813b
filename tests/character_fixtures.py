"""Shared helpers for the character tests: a tiny animated scene with a walking person, either
the procedural tube person or (where ``kubric.asset_tools.ensure_humans`` exists) the MakeHuman
"average" body walking CMU clip 01_01 — the same tests run on both."""

import numpy as np
import pytest

import kubric as kb
from kubric.assets.procedural_character import tube_person, walk_clip

RES = 64
KINDS = ("procedural", "humans")


def person_and_clip(kind: str, **kwargs):
    """(character, clip, clip_start seconds) of ``kind`` ("procedural" or "humans")."""
    if kind == "procedural":
        return tube_person(**kwargs), walk_clip(), 0.0
    from kubric import asset_tools
    if not hasattr(asset_tools, "ensure_humans"):
        pytest.skip("the humans source builder (kubric.asset_tools.ensure_humans) is not in this tree")
    characters, motions = asset_tools.ensure_humans()
    return characters.create("average", **kwargs), motions.create("cmu_01_01"), 2.0


def pixel_centres(w, h):
    c, r = np.meshgrid(np.arange(w) + 0.5, np.arange(h) + 0.5)
    return np.stack([c, r], -1)


def walking_scene(frames=4, moving_camera=True, kind="procedural"):
    """A person walking, seen by a camera that also moves; a floor behind. Frames 1..frames."""
    scene = kb.Scene(resolution=(RES, RES), frame_start=1, frame_end=frames, frame_rate=12)
    person, clip, clip_start = person_and_clip(kind, position=(0.2, 0.3, 0.0),
                                               euler=(0, 0, 0.5), scale=1.05)
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
    person.play(clip, clip_start=clip_start)
    return scene, person

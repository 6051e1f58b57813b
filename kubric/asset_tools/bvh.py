"""A BVH (Biovision hierarchy) motion-capture reader in numpy.

Semantics (the format's): each joint has an ``OFFSET`` from its parent and ``CHANNELS``; its local
transform at a frame is ``T(offset + position channels) · R``, ``R`` the product of the rotation
channels in the order listed (``Zrotation Yrotation Xrotation`` → ``Rz · Ry · Rx``, degrees);
world = parent world · local. ``End Site`` offsets give the tip of a chain. Units and axes are
the file's (CMU files: Y up, character facing +Z at zero rotation).

Every problem (truncated file, a non-number, NaN, unknown channel, a frame count that is not a
whole number ≥ 1 or does not match the data, a frame time ≤ 0, an offset or position beyond
±:data:`MAX_LENGTH`) raises :class:`BVHError` with one line naming the file and what is wrong.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from kubric.errors import InputError

CHANNELS = ("Xposition", "Yposition", "Zposition", "Xrotation", "Yrotation", "Zrotation")


#: the largest offset or root position a file may hold, in its own units (CMU's are inches)
MAX_LENGTH = 1e6


class BVHError(InputError):
    """A BVH file that cannot be read; the message names the file and the problem."""


@dataclass
class BVHJoint:
    name: str
    parent: int
    offset: np.ndarray
    channels: list[str]
    end_site: np.ndarray | None = None
    children: list[int] = field(default_factory=list)


@dataclass
class BVHMotion:
    joints: list[BVHJoint]
    frame_time: float
    data: np.ndarray  # (T, total channels)
    path: str = ""

    @property
    def names(self) -> list[str]:
        return [j.name for j in self.joints]

    @property
    def fps(self) -> float:
        return 1.0 / self.frame_time

    def local_transforms(self, frames=None) -> np.ndarray:
        """(T, J, 4, 4) local transforms; ``frames``: indices (default all)."""
        data = self.data if frames is None else self.data[frames]
        T = len(data)
        out = np.tile(np.eye(4), (T, len(self.joints), 1, 1))
        col = 0
        for j, joint in enumerate(self.joints):
            pos = np.tile(joint.offset, (T, 1))
            rot = np.tile(np.eye(3), (T, 1, 1))
            for ch in joint.channels:
                v = data[:, col]
                col += 1
                axis = "XYZ".index(ch[0])
                if ch.endswith("position"):
                    pos[:, axis] += v
                else:
                    rot = rot @ axis_rotation(axis, np.radians(v))
            out[:, j, :3, :3] = rot
            out[:, j, :3, 3] = pos
        return out

    def world_transforms(self, frames=None) -> np.ndarray:
        """(T, J, 4, 4) world transforms of the joints."""
        local = self.local_transforms(frames)
        world = np.empty_like(local)
        for j, joint in enumerate(self.joints):
            world[:, j] = local[:, j] if joint.parent < 0 else world[:, joint.parent] @ local[:, j]
        return world

    def rest_positions(self) -> np.ndarray:
        """(J, 3) joint positions with every channel at 0."""
        pos = np.zeros((len(self.joints), 3))
        for j, joint in enumerate(self.joints):
            pos[j] = joint.offset + (pos[joint.parent] if joint.parent >= 0 else 0.0)
        return pos


def axis_rotation(axis: int, angle: np.ndarray) -> np.ndarray:
    """(N, 3, 3) rotations by ``angle`` (radians, (N,)) about coordinate axis 0/1/2."""
    c, s = np.cos(angle), np.sin(angle)
    m = np.zeros(np.shape(angle) + (3, 3))
    i, j = [(1, 2), (2, 0), (0, 1)][axis]
    m[..., axis, axis] = 1.0
    m[..., i, i] = c
    m[..., j, j] = c
    m[..., i, j] = -s
    m[..., j, i] = s
    return m


def read_bvh(path: str | Path) -> BVHMotion:
    """Parse a BVH file (see the module docstring)."""
    path = Path(path)
    try:
        text = path.read_text(errors="strict")
    except (OSError, UnicodeDecodeError) as err:
        raise BVHError(f"{path}: cannot read as a text BVH file ({err})") from None
    tokens = text.split()
    pos = 0

    def fail(msg):
        raise BVHError(f"{path}: {msg}")

    def take():
        nonlocal pos
        if pos >= len(tokens):
            fail("truncated (the file ends inside the HIERARCHY section)")
        pos += 1
        return tokens[pos - 1]

    def number(what):
        tok = take()
        try:
            v = float(tok)
        except ValueError:
            fail(f"{what} is {tok!r}, not a number")
        if not np.isfinite(v):
            fail(f"{what} is {tok!r} (NaN/inf)")
        return v

    if take() != "HIERARCHY":
        fail("does not start with HIERARCHY")
    joints: list[BVHJoint] = []
    stack: list[int] = []
    tok = take()
    while tok != "MOTION":
        if tok in ("ROOT", "JOINT"):
            name = take()
            if take() != "{":
                fail(f"joint {name!r}: expected '{{'")
            parent = stack[-1] if stack else -1
            if tok == "ROOT" and joints:
                fail(f"a second ROOT {name!r} (only one skeleton per file is supported)")
            if take() != "OFFSET":
                fail(f"joint {name!r}: expected OFFSET")
            offset = np.array([number(f"joint {name!r} OFFSET") for _ in range(3)])
            if take() != "CHANNELS":
                fail(f"joint {name!r}: expected CHANNELS")
            n = int(number(f"joint {name!r} channel count"))
            chans = [take() for _ in range(n)]
            bad = [c for c in chans if c not in CHANNELS]
            if bad:
                fail(f"joint {name!r}: unknown channels {bad}; allowed: {list(CHANNELS)}")
            joints.append(BVHJoint(name, parent, offset, chans))
            if parent >= 0:
                joints[parent].children.append(len(joints) - 1)
            stack.append(len(joints) - 1)
        elif tok == "End":
            take()  # "Site"
            if take() != "{" or take() != "OFFSET":
                fail("End Site: expected '{ OFFSET'")
            if not stack:
                fail("End Site outside a joint")
            joints[stack[-1]].end_site = np.array([number("End Site OFFSET") for _ in range(3)])
            if take() != "}":
                fail("End Site: expected '}'")
        elif tok == "}":
            if not stack:
                fail("unbalanced '}'")
            stack.pop()
        else:
            fail(f"unexpected token {tok!r} in HIERARCHY")
        tok = take()
    if stack or not joints:
        fail("HIERARCHY is incomplete (unclosed joint or no joint)")
    if take() != "Frames:":
        fail("expected 'Frames:' after MOTION")
    n_frames = number("Frames")
    if n_frames != int(n_frames) or n_frames < 1:
        fail(f"Frames must be a whole number ≥ 1, got {n_frames:g}")
    n_frames = int(n_frames)
    if take() != "Frame" or take() != "Time:":
        fail("expected 'Frame Time:'")
    frame_time = number("Frame Time")
    if frame_time <= 0:
        fail(f"Frame Time must be > 0, got {frame_time}")
    n_ch = sum(len(j.channels) for j in joints)
    values = tokens[pos:]
    if len(values) != n_frames * n_ch:
        fail(f"truncated or malformed MOTION data: {len(values)} values, expected "
             f"{n_frames} frames × {n_ch} channels = {n_frames * n_ch}")
    try:
        data = np.array(values, dtype=np.float64).reshape(n_frames, n_ch)
    except ValueError:
        fail("MOTION data holds a value that is not a number")
    if not np.isfinite(data).all():
        frame = int(np.nonzero(~np.isfinite(data).all(axis=1))[0][0])
        fail(f"MOTION data holds NaN/inf (first at frame {frame})")
    lengths = [abs(v) for j in joints for v in (*j.offset, *(() if j.end_site is None
                                                             else j.end_site))]
    col = 0
    for joint in joints:
        for c in joint.channels:
            if c.endswith("position"):
                lengths.append(float(np.abs(data[:, col]).max()))
            col += 1
    if max(lengths) > MAX_LENGTH:
        fail(f"an offset or position of {max(lengths):g} file units is beyond ±{MAX_LENGTH:g} "
             "(a unit or scale error)")
    return BVHMotion(joints, frame_time, data, str(path))

"""Collision events from PyBullet contact points (pure Python; no engine import).

An event is a dict (the project-wide collision contract)::

    {"instances": (asset_a, asset_b),   # model assets; None for a body the scene does not know
     "frame": float,                    # scene frame of the physics step that produced it
     "force": float,                    # normal force in newtons
     "position": (3,) tuple,            # world-space contact point on asset_a (metres)
     "contact_normal": (3,) tuple}      # unit normal on asset_a, pointing towards asset_b

The order inside ``instances`` follows upstream Kubric: PyBullet's body B first, body A second, so
``position`` is PyBullet's ``positionOnB`` and ``contact_normal`` is ``contactNormalOnB``.

Merging (the default of ``PyBullet.run``): all contacts of the same unordered pair of bodies whose
steps fall in the same frame interval ``(f, f + 1]`` become one event, the strongest contact
(largest normal force) of the group; events are ordered by the first contact of each group.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from typing import Any

#: Contacts with a smaller normal force (newtons) are dropped (upstream Kubric's threshold).
DEFAULT_MIN_FORCE = 1e-6


def raw_events(points: Iterable[Sequence], assets_by_body: Mapping[int, Any], frame: float,
               step: int, min_force: float = DEFAULT_MIN_FORCE) -> list[dict]:
    """Events for the contact points of one physics step (``pybullet.getContactPoints`` tuples).

    ``step`` (the step's index within the run, from 1) and the PyBullet body pair are kept under
    the private keys ``"_step"`` and ``"_bodies"`` (removed by :func:`finalize`).
    """
    events = []
    for point in points:
        body_a, body_b = point[1], point[2]
        force = float(point[9])
        if force < min_force:
            continue
        events.append({
            "instances": (assets_by_body.get(body_b), assets_by_body.get(body_a)),
            "frame": float(frame),
            "force": force,
            "position": tuple(float(v) for v in point[6]),
            "contact_normal": tuple(float(v) for v in point[7]),
            "_bodies": (body_b, body_a),
            "_step": step,
        })
    return events


def merge_events(events: Iterable[dict], steps_per_frame: int) -> list[dict]:
    """One event per (frame interval, unordered body pair): the one with the largest force.

    Steps ``1..steps_per_frame`` form the first interval, and so on.
    """
    groups: dict[tuple, dict] = {}
    for event in events:
        key = ((event["_step"] - 1) // steps_per_frame, frozenset(event["_bodies"]))
        best = groups.get(key)
        if best is None or event["force"] > best["force"]:
            groups[key] = event
    return list(groups.values())


def finalize(events: Iterable[dict]) -> list[dict]:
    """Drop the private keys: events with exactly the contract's five keys."""
    return [{k: v for k, v in e.items() if not k.startswith("_")} for e in events]

"""People in recipes: character / motion source options, the procedural stand-in source, and
adding a person who performs a clip (shared by ``pose_estimation`` and MOVi-C–F's
``characters=N``; docs/characters.md)."""

from __future__ import annotations

import numpy as np

import kubric as kb
from kubric.assets.procedural_character import tube_person, walk_clip
from kubric.pipeline import Option, OptionError
from kubric.recipes.common import open_existing_source, source_location

PROCEDURAL = "procedural"


def character_location(value):
    """Option converter: ``procedural`` or an asset source (see :func:`source_location`)."""
    if isinstance(value, str) and value.strip().lower() == PROCEDURAL:
        return PROCEDURAL
    return source_location(value)


character_location.allowed = f"{PROCEDURAL!r}, or " + source_location.allowed
character_location.__name__ = "procedural|path|URL"


class ProceduralSource:
    """The built-in tube person / walk clip as a one-asset source (``asset_ids``, ``create``)."""

    def __init__(self, kind: str):
        self.kind = kind

    def asset_ids(self) -> list[str]:
        return ["tube_person"] if self.kind == "characters" else ["procedural_walk"]

    def create(self, asset_id: str, **kwargs):
        if self.kind == "characters":
            kwargs.setdefault("material", kb.PrincipledBSDFMaterial(
                color=kb.Color(0.55, 0.38, 0.28), roughness=0.6))
            return tube_person(**kwargs)
        return walk_clip(seconds=4.0)


def open_people_sources(character_source, motion_source) -> dict:
    """``{"characters": source, "motions": source}`` for the two options (module doc)."""
    out = {}
    humans = None
    for key, value in (("characters", character_source), ("motions", motion_source)):
        if value == PROCEDURAL:
            out[key] = ProceduralSource(key)
        elif value is not None:
            out[key] = open_existing_source(value, f"{key[:-1]}_source")
        else:
            if humans is None:
                from kubric import asset_tools
                if not hasattr(asset_tools, "ensure_humans"):
                    raise OptionError("the default humans source needs kubric.asset_tools."
                                      "ensure_humans (`kubric assets humans`), which this "
                                      "installation lacks; give character_source=procedural "
                                      "motion_source=procedural or source folders")
                humans = asset_tools.ensure_humans()
            out[key] = humans[0] if key == "characters" else humans[1]
        check_source_kind(out[key], key, value)
    return out


#: the asset type each people source must hold
SOURCE_KINDS = {"characters": "Character", "motions": "MotionClip"}


def check_source_kind(source, key: str, value) -> None:
    """OptionError (one line) unless ``source`` holds assets and all are of the type ``key``
    needs: a motion source given as ``character_source`` (or the reverse) is named as such."""
    db = getattr(source, "db", None)
    if db is None:  # the procedural stand-in
        return
    kinds = sorted({str(entry.get("asset_type")) for entry in db.values()})
    option = f"{key[:-1]}_source"
    if kinds != [SOURCE_KINDS[key]]:
        other = {v: k for k, v in SOURCE_KINDS.items()}.get(kinds[0]) if len(kinds) == 1 else None
        hint = f" (a {other[:-1]} source: give it as {other[:-1]}_source?)" if other else ""
        raise OptionError(f"{option}={str(value)!r} holds {kinds or 'no'} assets, not only "
                          f"{SOURCE_KINDS[key]} ones{hint}")


def asset_ids(source) -> list[str]:
    ids = source.asset_ids() if callable(getattr(source, "asset_ids", None)) else \
        list(source.all_asset_ids)
    return sorted(ids)


def source_options(when: str = "") -> tuple:
    """The ``character_source`` and ``motion_source`` options of a recipe with people (``when``
    prefixes their help, e.g. "with characters: ")."""
    return (Option(None, f"{when}character asset source (folder or URL), or 'procedural' (the "
                   "built-in tube person); default: the MakeHuman humans source",
                   type=character_location),
            Option(None, f"{when}motion-clip asset source (folder or URL), or 'procedural' (the "
                   "built-in walk); default: the humans source's clips",
                   type=character_location))


def add_person(scene, sources, rng, spot, name: str):
    """Add a character drawn from ``sources["characters"]`` performing a clip drawn from
    ``sources["motions"]`` over frames 0 .. frame_end + 1: random heading, random start time in
    the clip (so the scene's duration fits in it when it can; the clip holds its last pose after
    its end), placed so that it starts at ``spot`` (x, y) on the floor (the clip's root offset at
    its start cancelled). Random draws: character, clip, heading, start time. The person's
    metadata gets ``character_id``, ``motion_id``, ``motion_start`` (s), ``scale`` (its rest
    height, m) and ``is_dynamic`` (True)."""
    cid = _choice(rng, asset_ids(sources["characters"]))
    mid = _choice(rng, asset_ids(sources["motions"]))
    person = sources["characters"].create(cid, name=name)
    heading = kb.Quaternion(axis=(0, 0, 1), angle=float(rng.uniform(0, 2 * np.pi)))
    clip = sources["motions"].create(mid)
    seconds = (scene.frame_end + 1) / scene.frame_rate
    start = float(rng.uniform(0, max(clip.duration - seconds, 0.0)))
    offset = clip.sample([start])[1][0] * np.asarray(person.scale, np.float64)
    shift = heading.rotate(offset)
    person.position = (float(spot[0] - shift[0]), float(spot[1] - shift[1]), 0.0)
    person.quaternion = heading
    scene += person
    person.play(clip, start_frame=0, end_frame=scene.frame_end + 1, frame_rate=scene.frame_rate,
                clip_start=start)
    height = float(np.ptp(person.rest_bounds[:, 2]) * float(np.max(person.scale)))
    person.metadata = {**person.metadata, "character_id": cid, "motion_id": mid,
                       "motion_start": start, "scale": height, "is_dynamic": True}
    return person


def free_spots(rng, count: int, half: float, gap: float, tries: int = 100) -> list:
    """Up to ``count`` (x, y) points uniform in [−half, half]², at least ``gap`` apart (a point
    with no free place after ``tries`` draws is skipped)."""
    spots: list[np.ndarray] = []
    for _ in range(count):
        for _ in range(tries):
            cand = rng.uniform(-half, half, 2)
            if all(np.linalg.norm(cand - s) >= gap for s in spots):
                spots.append(cand)
                break
    return spots


def _choice(rng, items):
    items = list(items)
    return items[rng.randint(len(items))]

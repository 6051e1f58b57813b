"""Resuming only what the same options made: a re-run of ``generate`` into an output folder whose
complete scenes were made with other options refuses (one line naming the options that differ
and the ways out) instead of skipping them as done.

A scene's options are in its ``schema.json`` (``recipe``, ``options``:
:mod:`kubric.io.stored_schema`), in ``metadata.json["flags"]`` for scenes written before it. The
run compares the options its workers would be given (the recipe's :meth:`flags
<kubric.pipeline.recipe.Recipe.flags>` less the seed, as JSON) with those of the complete scenes it
would skip, or — when it skips none — with one complete scene of the folder, so that new seeds
are not added to scenes made otherwise. ``resume`` chooses:

* ``"same"`` (default): that check (an option a scene does not record — added to the recipe
  after the scene was made — counts as its default);
* ``"any"`` (``--resume-any``): skip complete scenes whatever made them (the check is off);
* ``"overwrite"`` (``--overwrite``): the requested seeds' complete scenes are deleted and made
  again; scenes of other seeds are left alone (and not checked).
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence

from kubric.errors import InputError, UsageError
from kubric.io import storage
from kubric.io.scene_dir import METADATA_FILE, SCHEMA_FILE, SUCCESS_FILE, scene_name

#: the ways a run treats complete scenes (see module doc)
RESUME_MODES = ("same", "any", "overwrite")
#: how many differing options the message names before "..."
SHOWN = 4


class OptionsChanged(UsageError):
    """The folder's complete scenes were made with other options than this run's."""


def run_options(recipe_spec: str, assignments: Sequence[str]) -> tuple[dict, dict]:
    """(the options and recipe name a run's workers record, the recipe's defaults), both as
    their JSON reads back."""
    from kubric.pipeline.recipe import get_recipe
    cls = get_recipe(recipe_spec)
    flags = cls.from_assignments(assignments).flags(0)
    flags.pop("seed", None)
    defaults = {name: opt.default for name, opt in cls.options.items()}
    return tuple(json.loads(json.dumps(d, default=str)) for d in (flags, defaults))


def stored_options(scene: str) -> dict | None:
    """Recipe name and options scene ``scene`` (a path or URL) was made with; None when it
    records none."""
    for name in (SCHEMA_FILE, METADATA_FILE):
        location = storage.join(scene, name)
        if not storage.exists(location):
            continue
        try:
            doc = json.loads(storage.read_bytes(location))
        except (OSError, ValueError) as err:
            raise InputError(f"{location!r} cannot be read: {err}") from None
        if not isinstance(doc, Mapping):
            continue
        if name == SCHEMA_FILE and isinstance(doc.get("options"), Mapping):
            return {"recipe": doc.get("recipe"), **doc["options"]}
        flags = doc.get("flags")
        if isinstance(flags, Mapping):
            return {k: v for k, v in flags.items() if k != "seed"}
    return None


def differences(stored: Mapping, wanted: Mapping,
                defaults: Mapping | None = None) -> list[str]:
    """``name (THERE there, NOW now)`` for each option whose values differ (the recipe first).
    An option the scene does not record (added to the recipe since) counts as its default."""
    out, defaults = [], defaults or {}
    for key in sorted(set(stored) | set(wanted), key=lambda k: (k != "recipe", k)):
        there, now = stored.get(key, defaults.get(key, "unset")), wanted.get(key, "unset")
        if there != now:
            out.append(f"{key} ({json.dumps(there)} there, {json.dumps(now)} now)")
    return out


def scenes_to_check(seeds: Sequence[int], complete: set[str]) -> list[str]:
    """Names of the scenes whose options a run compares: the complete ones it would skip, else
    the first complete scene of the folder."""
    skipped = [scene_name(s) for s in seeds if scene_name(s) in complete]
    return skipped or sorted(complete)[:1]


def check_same_options(out_root, seeds: Sequence[int], complete: set[str],
                       wanted: Mapping, defaults: Mapping | None = None) -> None:
    """:class:`OptionsChanged` (one line) when a complete scene the run would skip, or the
    folder's first when it skips none, was made with options other than ``wanted`` (an option
    the scene does not record counts as its value in ``defaults``)."""
    names = scenes_to_check(seeds, complete)
    for name in names:
        stored = stored_options(storage.join(out_root, name))
        if stored is None:
            continue
        diff = differences(stored, wanted, defaults)
        if diff:
            shown = "; ".join(diff[:SHOWN]) + ("; ..." if len(diff) > SHOWN else "")
            raise OptionsChanged(
                f"--out {str(out_root)!r} holds {len(complete)} complete scene(s) made with other "
                f"options ({name}: {shown}): give a new --out, or --overwrite to make the "
                f"requested seeds again, or --resume-any to keep the scenes there as they are")


def remove_requested(out_root, seeds: Sequence[int], complete: set[str]) -> list[str]:
    """Delete the complete scenes of ``seeds`` (``--overwrite``); returns their names."""
    removed = [scene_name(s) for s in seeds if scene_name(s) in complete]
    for name in removed:  # _SUCCESS first: a removal cut short leaves no complete-looking scene
        storage.remove(storage.join(out_root, name, SUCCESS_FILE))
        storage.remove(storage.join(out_root, name))
    return removed


__all__ = ["OptionsChanged", "RESUME_MODES", "check_same_options", "differences",
           "remove_requested", "run_options", "stored_options"]

"""Per-scene uids: the first ``Cube`` that joins a scene is ``Cube``, the next ``Cube.001``, then
``Cube.002`` … (upstream's, i.e. Blender's, naming), counted per name by each :class:`Scene`.

The counters belong to the scene, not to the process: the same scene built twice — in one process,
in two processes, after any number of other scenes or tests — has the same uids, and nothing needs
resetting. An asset gets its uid when it joins its first scene and keeps it (also in later scenes,
where another asset holding the same uid is an error naming both); before that its uid is its name.
Counters only grow: a removed asset's number is not given to a new one.
"""

from __future__ import annotations


def _numbered(name: str, count: int) -> str:
    return name if count == 0 else f"{name}.{count:03d}"


class SceneUids:
    """The uid counters of one scene and the uids its assets hold."""

    def __init__(self) -> None:
        self._counts: dict[str, int] = {}
        self._holders: dict[str, object] = {}

    def claim(self, asset) -> str:
        """Give ``asset`` its uid if it has none yet (the next free number of its name), and record
        it as the holder of that uid in this scene. ``ValueError`` when another asset of the
        scene holds the uid already (possible only for an asset that joined another scene first).
        """
        uid = asset._uid
        if uid is None:
            count = self._counts.get(asset.name, 0)
            while _numbered(asset.name, count) in self._holders:
                count += 1
            uid = _numbered(asset.name, count)
            self._counts[asset.name] = count + 1
        holder = self._holders.get(uid)
        if holder is not None and holder is not asset:
            raise ValueError(f"cannot add {type(asset).__name__} {uid!r}: this scene already has "
                             f"another asset with uid {uid!r} (an asset keeps the uid of the first "
                             "scene it joined)")
        asset._uid = uid
        self._holders[uid] = asset
        return uid

    def release(self, asset) -> None:
        """Forget ``asset`` (removed from the scene); its number is not reused."""
        if self._holders.get(asset._uid) is asset:
            del self._holders[asset._uid]


__all__ = ["SceneUids"]

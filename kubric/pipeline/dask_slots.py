"""Scene slots on a Dask cluster: how many scenes each worker runs at once, on any cluster.

A scene slot runs one scene (one ``python -m kubric worker`` subprocess with
``--threads-per-scene`` render threads). Two kinds of cluster are served:

* **resource** — some workers offer the Dask resource ``scene`` (``dask worker ... --resources
  scene=1``, the ``local`` and ``slurm`` clusters kubric starts). Every task asks for
  ``scene=1``, so the scheduler runs at most that many scenes per worker; the client keeps
  ``2 × (Σ scene resources)`` tasks in flight, enough to keep every slot busy.
* **threads** — no worker offers ``scene`` (a cluster started as it is: ``dask worker ADDRESS``,
  a Kubernetes operator, dask-jobqueue defaults, a managed service). Each worker gets
  ``max(1, nthreads // threads_per_scene)`` slots, and the client keeps exactly one task per free
  slot in flight, each pinned to its worker (a *loose* restriction: when that worker dies, the
  scheduler runs the task elsewhere). So a worker started with 8 threads renders 8 one-thread
  scenes, or 2 scenes with ``--threads-per-scene 4``.

Either way the client holds only a bounded window of futures, whatever the number of scenes
(10⁴ scenes cost the client what 10³ do). Workers that join or leave are seen within
``refresh`` seconds (the scheduler's worker list is fetched again).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

#: the Dask resource a scene asks for where workers offer it
RESOURCE = "scene"


@dataclass
class Slot:
    """One task's claim: the submit arguments, and the worker it was pinned to (threads mode)."""

    kwargs: dict
    worker: str | None = None


@dataclass
class SceneSlots:
    """Client-side accounting of the cluster's scene slots (module doc). Build with the client
    and ``threads_per_scene``; :meth:`take` a slot before submitting a task, :meth:`give_back`
    it when the task's future is done."""

    client: object
    threads_per_scene: int = 1
    refresh: float = 2.0
    mode: str | None = None                # "resource" / "threads"; None until workers exist
    per_worker: dict[str, int] = field(default_factory=dict)
    busy: dict[str, int] = field(default_factory=dict)
    in_flight: int = 0
    _fetched: float = -1e9

    def update(self, force: bool = False) -> None:
        """Fetch the workers again (at most every ``refresh`` s unless ``force``)."""
        now = time.monotonic()
        if not force and now - self._fetched < self.refresh:
            return
        self._fetched = now
        workers = self.client.scheduler_info(n_workers=-1).get("workers", {})
        offered = {a: int(w.get("resources", {}).get(RESOURCE, 0) or 0)
                   for a, w in workers.items()}
        if self.mode is None and workers:
            self.mode = "resource" if any(offered.values()) else "threads"
        if self.mode == "resource":
            self.per_worker = {a: n for a, n in offered.items() if n > 0}
        elif self.mode == "threads":
            self.per_worker = {a: max(1, int(w.get("nthreads", 1)) // self.threads_per_scene)
                               for a, w in workers.items()}

    @property
    def total(self) -> int:
        return sum(self.per_worker.values())

    def take(self) -> Slot | None:
        """Submit arguments for one more task, or None while every slot is taken."""
        self.update()
        if self.mode == "resource":
            if self.in_flight >= 2 * self.total:
                return None
            self.in_flight += 1
            return Slot({"resources": {RESOURCE: 1}})
        if self.mode != "threads":
            return None
        free = [(n - self.busy.get(a, 0), a) for a, n in sorted(self.per_worker.items())]
        best = max(free, default=(0, None))
        if best[0] <= 0:
            return None
        self.busy[best[1]] = self.busy.get(best[1], 0) + 1
        self.in_flight += 1
        return Slot({"workers": [best[1]], "allow_other_workers": True}, best[1])

    def give_back(self, slot: Slot) -> None:
        self.in_flight -= 1
        if slot.worker is not None:
            left = self.busy.get(slot.worker, 0) - 1
            if left > 0:
                self.busy[slot.worker] = left
            else:
                self.busy.pop(slot.worker, None)

    def describe(self) -> str:
        """One line for the log: how scenes are placed on this cluster."""
        self.update(force=True)
        if self.mode == "resource":
            return (f"{len(self.per_worker)} workers offer {self.total} '{RESOURCE}' slots "
                    f"(one scene each)")
        if self.mode == "threads":
            return (f"no worker offers the '{RESOURCE}' resource: {self.total} slots from the "
                    f"workers' threads ({len(self.per_worker)} workers, nthreads // "
                    f"{self.threads_per_scene} each)")
        return "no workers yet: waiting for workers to join"


def uses_resource(client) -> bool:
    """True when some worker of ``client``'s cluster offers the ``scene`` resource (tasks may
    ask for it); False for a cluster of plain workers (or none yet)."""
    workers = client.scheduler_info(n_workers=-1).get("workers", {})
    return any((w.get("resources", {}) or {}).get(RESOURCE) for w in workers.values())


__all__ = ["RESOURCE", "SceneSlots", "Slot", "uses_resource"]

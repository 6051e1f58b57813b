"""One pack at a time per object-store output: a lease, since object stores have no locks.

``kubric pack --out s3://bucket/ds`` takes the lease before it looks at the output and keeps it
until the commit ends (:mod:`kubric.datasets.store_commit`), so a second pack of the same URL
never stages into, clears or commits over the first's files: it refuses at once (exit status 3,
:class:`~kubric.io.output_lock.OutputBusy`) and deletes nothing but its own lease.

The lease is one object per run, ``OUT/.kubric-pack-leases/TOKEN.json`` holding the host, the
process id and the time it was last renewed. A run writes its object, then lists the folder:
when any other live lease is there it removes its own and refuses (two runs starting together
may both refuse; neither writes). Stores with read-after-write consistency (S3, GCS, MinIO)
make a run that listed only its own lease the one holder. A holder renews its lease every
:data:`RENEW_S` seconds from a thread; a lease not renewed for :data:`STALE_S` seconds, or one
of a process on this host that no longer runs (a ``kill -9``), is stale and removed by the next
run.
"""

from __future__ import annotations

import json
import os
import socket
import threading
import time
import uuid

from kubric.io import storage
from kubric.io.output_lock import OutputBusy
from kubric.io.paths import pid_alive

LEASES = ".kubric-pack-leases"
RENEW_S = 30.0
STALE_S = 300.0


def _stale(lease: dict | None, now: float) -> bool:
    if not isinstance(lease, dict):
        return True
    if lease.get("host") == socket.gethostname() and isinstance(lease.get("pid"), int) \
            and not pid_alive(lease["pid"]):
        return True
    renewed = lease.get("renewed")
    return not isinstance(renewed, int | float) or now - renewed > STALE_S


class StoreLease:
    """``with StoreLease(out):`` — the lease of ``out`` (a URL) for this run (module doc)."""

    def __init__(self, out: str):
        self.out = out
        self.token = uuid.uuid4().hex
        self.location = storage.join(out, LEASES, f"{self.token}.json")
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def _write(self) -> None:
        storage.write_bytes(self.location, json.dumps(
            {"host": socket.gethostname(), "pid": os.getpid(), "renewed": time.time()}).encode())

    def _others(self) -> list[tuple[str, dict | None]]:
        folder = storage.join(self.out, LEASES)
        found = []
        for name in storage.listdir(folder):
            if name == f"{self.token}.json":
                continue
            try:
                lease = json.loads(storage.read_bytes(storage.join(folder, name)))
            except (FileNotFoundError, ValueError):
                lease = None
            found.append((name, lease))
        return found

    def acquire(self) -> StoreLease:
        now = time.time()
        for name, lease in self._others():
            if _stale(lease, now):
                storage.remove(storage.join(self.out, LEASES, name))
        self._write()
        live = [lease for _, lease in self._others() if not _stale(lease, time.time())]
        if live:
            storage.remove(self.location)
            holder = live[0] or {}
            raise OutputBusy(f"--out {self.out!r} is being packed by another run (host "
                             f"{holder.get('host')!r}, pid {holder.get('pid')}); wait for it "
                             "to finish (nothing was written or removed)")
        self._thread = threading.Thread(target=self._renew, daemon=True, name="kubric-lease")
        self._thread.start()
        return self

    def _renew(self) -> None:
        while not self._stop.wait(RENEW_S):
            try:
                self._write()
            except Exception:  # a store hiccup: the next renewal tries again
                pass

    def release(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5)
        try:
            storage.remove(self.location)
        except Exception:  # the lease goes stale on its own
            pass

    def __enter__(self) -> StoreLease:
        return self.acquire()

    def __exit__(self, *exc) -> None:
        self.release()


__all__ = ["LEASES", "RENEW_S", "STALE_S", "StoreLease"]

"""One writer per output folder: ``kubric pack --out D`` and ``kubric generate --out D`` hold an
exclusive ``flock`` on a lock file while they write; a second run on the same output refuses at
once with one line naming the holder's process id.

The lock file (``.NAME.lock`` beside a dataset directory, ``.kubric-generate.lock`` inside a
scene folder) holds the holder's pid and is removed when the holder ends normally. The kernel
drops a ``flock`` when its process dies, so a lock file left by ``kill -9`` does not block the next
run. Local paths only (object stores have no locks).
"""

from __future__ import annotations

import fcntl
import os
import pathlib

from kubric.errors import KubricError


class OutputBusy(KubricError, RuntimeError):
    """The output is being written by another run (one line; exit status 3 in every command,
    docs/exit-codes.md: try again when that run has ended)."""

    exit_code = 3


class OutputLock:
    """``with OutputLock(path, what):`` — exclusive, non-blocking; raises :class:`OutputBusy`."""

    def __init__(self, path, what: str):
        self.path = pathlib.Path(path)
        self.what = what
        self._fd: int | None = None

    def acquire(self) -> OutputLock:
        self.path.parent.mkdir(parents=True, exist_ok=True)
        while True:
            fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                holder = os.read(fd, 32).decode(errors="replace").strip() or "unknown"
                os.close(fd)
                # (a lock file whose process died is not locked: the kernel dropped it)
                raise OutputBusy(f"{self.what} is being written by another run (pid {holder}, "
                                 f"lock {str(self.path)!r}); wait for it to finish or stop "
                                 "it") from None
            try:  # the holder before us may have removed the file after we opened it
                same = os.stat(self.path).st_ino == os.fstat(fd).st_ino
            except FileNotFoundError:
                same = False
            if same:
                break
            os.close(fd)
        os.ftruncate(fd, 0)
        os.write(fd, f"{os.getpid()}\n".encode())
        self._fd = fd
        return self

    def release(self) -> None:
        if self._fd is None:
            return
        try:
            self.path.unlink(missing_ok=True)
        finally:
            os.close(self._fd)
            self._fd = None

    def __enter__(self) -> OutputLock:
        return self.acquire()

    def __exit__(self, *exc) -> None:
        self.release()

"""Temporary folders owned by the process that made them, removed when it exits: normally, by an
exception, or by SIGTERM / SIGINT.

Why ``atexit`` and not only ``try/finally``: a signal that arrives while Blender runs Python code
of its own (e.g. during ``import bpy``) raises ``SystemExit`` inside Blender, which reports it
with ``PyErr_Print`` — and CPython then ends the process at once (``Py_Exit``), skipping every
``finally`` of ours. ``Py_Exit`` still runs the ``atexit`` handlers, so owned paths are removed
there too. Only SIGKILL leaves them behind; the next run removes those of dead processes
(:func:`private_tmpdir`, and the worker's ``remove_stale`` for scene work directories).
"""

from __future__ import annotations

import atexit
import os
import pathlib
import re
import shutil
import signal
import tempfile
import threading

from kubric.io.paths import pid_alive  # noqa: F401  (also public here: worker, tests)

#: prefix of a process's private temporary folder: ``kubric-tmp-{pid}-`` + a random suffix (mkdtemp's)
PRIVATE_PREFIX = "kubric-tmp-"
_PRIVATE_RE = re.compile(rf"^{PRIVATE_PREFIX}(\d+)-")

_owned: dict[pathlib.Path, int] = {}  # path -> the pid that owns it (a fork inherits the dict)
_lock = threading.Lock()
_registered = False


def own(path) -> pathlib.Path:
    """Remove ``path`` (a folder) when this process exits, unless :func:`release` d first."""
    global _registered
    path = pathlib.Path(path)
    with _lock:
        _owned[path] = os.getpid()
        if not _registered:
            atexit.register(remove_owned)
            _registered = True
    return path


def release(path) -> None:
    """``path`` is no longer temporary (renamed into place, or removed by its owner)."""
    with _lock:
        _owned.pop(pathlib.Path(path), None)


def remove_owned(ignore_signals: bool = True) -> None:
    """Remove every owned folder of this process (the atexit handler). The process is ending:
    a further SIGTERM / SIGINT is ignored rather than allowed to cut the removal short."""
    if ignore_signals and threading.current_thread() is threading.main_thread():
        for sig in (signal.SIGTERM, signal.SIGINT):
            signal.signal(sig, signal.SIG_IGN)
    with _lock:
        mine = [p for p, pid in _owned.items() if pid == os.getpid()]
        for p in mine:
            del _owned[p]
    for path in mine:
        shutil.rmtree(path, ignore_errors=True)


def remove_stale_private(parent) -> list[pathlib.Path]:
    """Remove ``kubric-tmp-PID-*`` folders under ``parent`` whose process no longer runs (left by
    SIGKILL); returns them."""
    parent = pathlib.Path(parent)
    stale = []
    try:
        entries = list(parent.iterdir())
    except OSError:
        return stale
    for entry in entries:
        m = _PRIVATE_RE.match(entry.name)
        if m and entry.is_dir() and not pid_alive(int(m.group(1))):
            shutil.rmtree(entry, ignore_errors=True)
            stale.append(entry)
    return stale


def private_tmpdir() -> pathlib.Path:
    """Give this process its own temporary folder ``$TMPDIR/kubric-tmp-{pid}-<random>``, owned
    (removed at exit), and point ``TMPDIR`` and :mod:`tempfile` at it, so that whatever this
    process and its children put in temporary space — Blender's ``blender_*`` session folders
    included — goes with it. Stale folders of dead processes are removed first."""
    parent = pathlib.Path(tempfile.gettempdir())
    remove_stale_private(parent)
    path = own(tempfile.mkdtemp(prefix=f"{PRIVATE_PREFIX}{os.getpid()}-", dir=parent))
    os.environ["TMPDIR"] = str(path)
    tempfile.tempdir = str(path)
    return path


def exit_on_signal(signum, _frame):
    """Signal handler: unwind like an exception (``finally`` blocks and atexit handlers run);
    exit status 128 + signal number, as a shell reports a process killed by that signal."""
    raise SystemExit(128 + signum)


def handle_termination() -> None:
    """SIGTERM (what Slurm and ``kill`` send) and SIGINT (Ctrl-C) both end this process through
    :func:`exit_on_signal`. Main thread only."""
    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, exit_on_signal)

"""Fault points for tests: make a process fail at one exact moment a plain ``kill`` cannot hit.

``KUBRIC_FAULT=POINT:ACTION[,POINT:ACTION...]`` (unset in normal use: :func:`point` is then a
dictionary lookup). Each named moment in the code calls ``point("pack.after_shard_rename")``;
when the environment names it, the action runs there:

* ``kill`` — SIGKILL this process (what ``kill -9``, the OOM killer or a lost node do);
* ``term`` / ``int`` — send SIGTERM / SIGINT to this process (the handlers run);
* ``enospc`` — raise ``OSError(ENOSPC)`` (a full disk);
* ``sleep`` — wait ``KUBRIC_FAULT_SLEEP`` seconds (default 1): make a step slow enough to be hit;
* ``call`` — run ``KUBRIC_FAULT_CALL`` (a ``module:function`` taking the point's name), e.g. to
  change a file between two steps.

Points: ``pack.encode_scene`` (before each scene is encoded, in the encoding process),
``pack.shard_write`` (before each record is written), ``pack.shard_renamed`` (after each final
shard rename), ``pack.finalised`` (the dataset finished in the work folder, before ``--verify``),
``pack.before_swap``, ``pack.old_moved`` (an old dataset moved aside, the new one not yet in
place), ``worker.generated`` (a scene's recipe returned, before ``_SUCCESS``),
``export.scene_written`` (an export wrote one scene's records into its temporary files). The hostile tests
(``tests/test_hostile_*.py``) and ``benchmarks/bench_pack_signals.py`` use them.
"""

from __future__ import annotations

import errno
import importlib
import os
import signal

ENV = "KUBRIC_FAULT"
CALL_ENV = "KUBRIC_FAULT_CALL"


def _actions() -> dict[str, str]:
    raw = os.environ.get(ENV, "")
    out = {}
    for part in filter(None, (p.strip() for p in raw.split(","))):
        name, _, action = part.rpartition(":")
        out[name] = action
    return out


def point(name: str, path=None) -> None:
    """The fault point ``name`` (``path``: the file being written there, for ``enospc``)."""
    if ENV not in os.environ:
        return
    action = _actions().get(name)
    if action is None:
        return
    if action == "kill":
        os.kill(os.getpid(), signal.SIGKILL)
    elif action in ("term", "int"):
        os.kill(os.getpid(), signal.SIGTERM if action == "term" else signal.SIGINT)
    elif action == "enospc":
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), None if path is None else str(path))
    elif action == "sleep":
        import time
        time.sleep(float(os.environ.get("KUBRIC_FAULT_SLEEP", "1")))
    elif action == "call":
        module, _, fn = os.environ[CALL_ENV].partition(":")
        getattr(importlib.import_module(module), fn)(name)
    else:
        raise ValueError(f"{ENV}: unknown action {action!r} at {name!r} (kill, term, int, "
                         "enospc, sleep, call)")

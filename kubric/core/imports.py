"""Importing a library that swallows Ctrl-C.

Some libraries guard their optional imports with ``except BaseException`` (trimesh does, in
``trimesh/__init__.py`` and ``trimesh/base.py``): a Ctrl-C that lands while they import is caught
and stored, and the command goes on as if nothing happened. :func:`uninterrupted_import`
imports such a module with SIGINT and SIGTERM recorded instead of handled (a Python handler
that only notes the signal) and raises the first one right after, through the handler that was
installed before, so the interrupt is never lost.
"""

from __future__ import annotations

import importlib
import signal
import sys
import threading

_HELD = (signal.SIGINT, signal.SIGTERM)


def uninterrupted_import(name: str):
    """``importlib.import_module(name)`` with interrupts deferred to its end (module doc)."""
    if name in sys.modules:
        return sys.modules[name]
    if threading.current_thread() is not threading.main_thread():
        return importlib.import_module(name)
    received: list[int] = []
    saved = {s: signal.getsignal(s) for s in _HELD}
    saved = {s: h for s, h in saved.items() if h is not None}  # (None: not Python's to replace)
    for sig in saved:
        signal.signal(sig, lambda signum, _frame: received.append(signum))
    try:
        return importlib.import_module(name)
    finally:
        for sig, handler in saved.items():
            signal.signal(sig, handler)
        if received:
            signal.raise_signal(received[0])  # the handler of before: KeyboardInterrupt, exit


__all__ = ["uninterrupted_import"]

"""The benchmarks' tiny-size mode: ``KUBRIC_BENCH_SMOKE=1`` (tests/test_benchmarks_smoke.py).

A smoke run takes every code path of a benchmark at the smallest size that still runs it (one
scene, 16-pixel frames, one sample, one repetition): its numbers mean nothing, its exit status
and its printed rows do. It never writes into the repository: what a full run records under
``docs/`` goes to a temporary folder (:func:`output`).

Benchmarks run as scripts (``python benchmarks/bench_x.py``), so they import this module as
``smoke_mode`` from their own folder.
"""

from __future__ import annotations

import os
import pathlib
import shutil
import tempfile

VARIABLE = "KUBRIC_BENCH_SMOKE"
_value = os.environ.get(VARIABLE, "")
if _value not in ("", "0", "1"):
    raise SystemExit(f"{VARIABLE}={_value!r}: allowed values are '', '0' and '1'")
#: True in a smoke run
SMOKE = _value == "1"


def size(full, tiny):
    """``tiny`` in a smoke run, else ``full`` (a scene count, a resolution, a repetition count...)."""
    return tiny if SMOKE else full


def output(path: pathlib.Path | None) -> pathlib.Path | None:
    """Where a benchmark writes the result file ``path`` (a docs page, a recorded data set): the
    path itself in a full run; in a smoke run a copy of it (when it exists: a page rewritten
    between markers needs the rest) in a fresh temporary folder, so that the repository is never
    written (``None`` stays ``None``)."""
    if not SMOKE or path is None:
        return path
    path = pathlib.Path(path)
    copy = pathlib.Path(tempfile.mkdtemp(prefix="kubric-bench-smoke-")) / path.name
    if path.is_file():
        shutil.copyfile(path, copy)
    return copy

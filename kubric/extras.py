"""Optional packages and the extra that installs each: a command that needs one that is not
installed ends in one line naming it and the ``pip install 'kubric[EXTRA]'`` that brings it.

:func:`require` checks up front (``kubric pack`` before it reads a scene, ``generate --cluster``
before it starts a cluster); :func:`missing_extra` turns a ``ModuleNotFoundError`` raised
anywhere under the ``kubric`` command into that line (:func:`kubric.cli.main`). The table
follows ``[project.optional-dependencies]`` in ``pyproject.toml`` (a test checks it).
"""

from __future__ import annotations

import importlib.util

from kubric.errors import KubricError

#: import name → the extra that installs it (the smallest one that does)
EXTRA_OF = {
    "tensorflow_datasets": "datasets", "array_record": "datasets", "etils": "datasets",
    "grain": "datasets", "cv2": "datasets",
    "dask": "cluster", "distributed": "cluster", "dask_jobqueue": "cluster", "bokeh": "cluster",
    "fsspec": "cluster",
    "s3fs": "s3", "gcsfs": "gcs", "embreex": "raycast", "coacd": "coacd", "h5py": "events",
    "tensorflow": "tf", "torch": "torch", "jax": "jax", "jaxlib": "jax",
}


class MissingExtra(KubricError):
    """An optional package a command needs is not installed (exit status 1)."""


def installed(module: str) -> bool:
    """Whether top-level module ``module`` can be imported here (without importing it)."""
    try:
        return importlib.util.find_spec(module) is not None
    except (ImportError, ValueError):
        return False


def message(module: str, what: str | None = None) -> str:
    """The one line for optional module ``module`` not installed (``what`` needs it)."""
    extra = EXTRA_OF[module]
    needs = f"{what} needs" if what else "needs"
    return (f"{needs} the optional package {module!r}, which is not installed: "
            f"pip install 'kubric[{extra}]'")


def require(what: str, *modules: str) -> None:
    """:class:`MissingExtra` (one line) naming the first of ``modules`` not installed."""
    for module in modules:
        if not installed(module):
            raise MissingExtra(message(module, what))


def missing_extra(err: BaseException) -> str | None:
    """The one line for ``err`` when it is a ``ModuleNotFoundError`` of an optional package
    that is not installed; None otherwise (a bug, or a broken install: keep the traceback)."""
    if not isinstance(err, ModuleNotFoundError) or not err.name:
        return None
    top = err.name.split(".")[0]
    if top not in EXTRA_OF or installed(top):
        return None
    return message(top)


__all__ = ["EXTRA_OF", "MissingExtra", "installed", "message", "missing_extra", "require"]

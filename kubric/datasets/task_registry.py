"""The task registry: :class:`Task` and :func:`register_task` (the built-in tasks are in
:mod:`kubric.datasets.tasks` and :mod:`kubric.datasets.multiview_tasks`, which register with it;
the module doc of :mod:`kubric.datasets.tasks` says how to add one)."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

from kubric.datasets.layout import DatasetError


@dataclasses.dataclass(frozen=True)
class Task:
    """A registered task (see module doc). ``requires``: feature names (or name prefixes such as
    ``camera``) a dataset must have for the task to serve it (default: ``features``);
    ``extra_features(schema, options)`` adds top-level features to decode that depend on the
    options and the dataset (e.g. ``multiview``'s optional layers); ``wants_schema`` passes the
    dataset's schema to ``fn`` as ``schema=``."""

    name: str
    fn: Callable | None
    features: tuple[str, ...] | None = None
    per_frame: bool = False
    options: tuple[str, ...] = ()
    doc: str = ""
    requires: tuple[str, ...] = ()
    extra_features: Callable | None = None
    wants_schema: bool = False

    def check_options(self, options: dict) -> dict:
        unknown = sorted(set(options) - set(self.options))
        if unknown:
            raise DatasetError(f"task {self.name!r}: unknown option(s) {unknown}; options: "
                               f"{list(self.options) or 'none'}")
        return dict(options)

    def missing(self, schema) -> list[str]:
        """The required feature names (or prefixes) ``schema`` lacks."""
        names = schema.names
        return [r for r in self.requires or self.features or ()
                if r not in names and not any(n.startswith(r + "/") for n in names)]

    def decode_keys(self, schema, options: dict) -> tuple[str, ...] | None:
        """Top-level features to decode (None: all)."""
        if self.features is None:
            return None
        extra = tuple(self.extra_features(schema, options)) if self.extra_features else ()
        return tuple(dict.fromkeys(self.features + extra))

    def __call__(self, example: dict, frame, source) -> dict:
        if self.fn is None:
            return example
        if self.wants_schema:
            return self.fn(example, frame, schema=source.schema, **source.task_options)
        return self.fn(example, frame, **source.task_options)


TASKS: dict[str, Task] = {}


def register_task(name: str, features: tuple[str, ...] | None = None, per_frame: bool = False,
                  options: tuple[str, ...] = (), requires: tuple[str, ...] = (),
                  extra_features: Callable | None = None, wants_schema: bool = False):
    """Decorator registering ``fn(example, frame, **options) -> dict`` as task ``name``
    (:class:`Task` for ``requires``, ``extra_features`` and ``wants_schema``)."""
    def wrap(fn):
        TASKS[name] = Task(name, fn, tuple(features) if features else None, per_frame,
                           tuple(options), (fn.__doc__ or "").strip().split("\n")[0],
                           tuple(requires), extra_features, wants_schema)
        return fn
    return wrap


def servable_tasks(schema) -> list[str]:
    """The names of the registered tasks that a dataset of ``schema`` can serve."""
    return [name for name in sorted(TASKS) if not TASKS[name].missing(schema)]


def check_servable(task: Task, schema, where: str) -> None:
    """One-line :class:`DatasetError` when ``task`` cannot read a dataset of ``schema``."""
    missing = task.missing(schema)
    if missing:
        raise DatasetError(f"task {task.name!r} cannot read {where} (schema {schema.name!r}): it "
                           f"needs {missing}; this dataset serves the tasks "
                           f"{', '.join(servable_tasks(schema))}")


TASKS["all"] = Task("all", None, None, False, (), "every feature, nested numpy dict")


def get_task(name) -> Task:
    if isinstance(name, Task):
        return name
    if name is None:
        return TASKS["all"]
    if name not in TASKS:
        raise DatasetError(f"unknown task {name!r} (tasks: {', '.join(sorted(TASKS))})")
    return TASKS[name]

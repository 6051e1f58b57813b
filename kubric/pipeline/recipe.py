"""The recipe (worker) contract and the recipe registry.

A recipe turns ``(seed, options)`` into the files of one scene directory. Write one as a class::

    class Tiny(Recipe, name="tiny"):
        '''One line shown by `kubric recipes`.'''
        frames = Option(4, "number of frames", low=1)

        def generate(self, seed: int, out_dir: pathlib.Path) -> None:
            ...  # write files into out_dir (never _SUCCESS: the worker writes it)

or as a function with :func:`recipe`::

    @recipe("tiny", frames=Option(4, "number of frames", low=1))
    def tiny(seed, options, out_dir): ...

Subclassing with ``name=`` registers the recipe. A recipe owns its output contract: ``schema`` (a
:class:`~kubric.io.schema.Schema` named like the recipe) and ``variants`` (schemas of the same
scenes with more features, e.g. ``movi_a_tracks``) are registered with it; every built-in recipe
must declare one (a TypeError at import otherwise), and writes its scenes with
:func:`kubric.io.scene_writer.write_scene`, which checks them against it.

``Recipe(**values)`` converts and checks every option at once (an
:class:`~kubric.pipeline.options.OptionError` with a one-line message otherwise) and then calls
:meth:`Recipe.check` for cross-option checks, all before any rendering. The seed alone
determines the scene: ``generate`` must draw every random number from
``numpy.random.RandomState(seed)`` (or generators derived from it).
"""

from __future__ import annotations

import abc
import dataclasses
import importlib
import importlib.util
import pathlib
import sys
import types
from collections.abc import Callable, Mapping
from typing import Any, ClassVar

from kubric.errors import InputError
from kubric.io import scene_dir
from kubric.io.json_io import read_json
from kubric.io.schema import Schema, SchemaError, get_schema, register_schema
from kubric.io.stored_schema import document_schema, read_document, register_variants
from kubric.pipeline.options import Option, OptionError, convert_all, parse_assignments

#: registered recipes by name.
REGISTRY: dict[str, type[Recipe]] = {}

#: modules imported to register the built-in recipes.
BUILTIN_MODULES = ("kubric.recipes",)


class Recipe(abc.ABC):
    """Base class of recipes (see module doc).

    Attributes:
      name: registry name (set by ``class X(Recipe, name="...")``).
      options: ``{name: Option}`` declared on the class and its bases.
      values: ``{name: value}`` of this instance, converted and checked.
      schema: the output contract of its scenes (None only for recipes outside
        ``kubric.recipes`` that are never packed, e.g. a test's).
      variants: further schemas over the same scenes (e.g. with point tracks).
      internal: a tool, not a dataset (``bench``): ``kubric recipes`` lists it last, marked.
    """

    name: ClassVar[str] = ""
    internal: ClassVar[bool] = False
    options: ClassVar[dict[str, Option]] = {}
    schema: ClassVar[Schema | None] = None
    variants: ClassVar[tuple[Schema, ...]] = ()

    def __init_subclass__(cls, name: str | None = None, **kwargs):
        super().__init_subclass__(**kwargs)
        options: dict[str, Option] = {}
        for klass in reversed(cls.__mro__):
            for attr, value in vars(klass).items():
                if isinstance(value, Option):
                    options[attr] = value
        cls.options = options
        if name is not None:
            if name in REGISTRY and REGISTRY[name].__qualname__ != cls.__qualname__:
                raise ValueError(f"recipe name {name!r} is already taken by "
                                 f"{REGISTRY[name].__module__}.{REGISTRY[name].__qualname__}")
            cls.name = name
            _register_schemas(cls)
            REGISTRY[name] = cls
        elif not cls.name:
            cls.name = cls.__name__

    def __init__(self, **values: Any):
        self.values = convert_all(self.options, values, self.name)
        self.check()

    @classmethod
    def from_assignments(cls, pairs) -> Recipe:
        """Build from ``["key=value", ...]`` (the CLI's ``--set``)."""
        return cls(**parse_assignments(pairs))

    @classmethod
    def description(cls) -> str:
        doc = (cls.__doc__ or "").strip()
        return doc.splitlines()[0] if doc else ""

    def check(self) -> None:
        """Cross-option checks; raise OptionError with a one-line message. Default: none."""
        return None

    def prepare(self) -> None:
        """Once per dataset, in the runner's process, before any worker starts (e.g. build the
        default asset sources so that parallel workers do not race to build them)."""
        return None

    @abc.abstractmethod
    def generate(self, seed: int, out_dir: pathlib.Path) -> None:
        """Write the scene for ``seed`` into ``out_dir`` (which exists and is empty)."""

    def flags(self, seed: int) -> dict[str, Any]:
        """Every worker argument for ``metadata.json["flags"]``: recipe name, seed, options."""
        out: dict[str, Any] = {"recipe": self.name, "seed": int(seed)}
        for key, value in self.values.items():
            out[key] = str(value) if isinstance(value, pathlib.Path) else value
        return out


def _register_schemas(cls: type[Recipe]) -> None:
    """Register the schemas a recipe class declares; TypeError (one line) for a built-in recipe
    without one, or a declaration that is not a Schema."""
    if cls.schema is None:
        if cls.__module__.startswith(BUILTIN_MODULES):
            raise TypeError(f"recipe {cls.name!r} ({cls.__module__}.{cls.__qualname__}) declares "
                            "no schema: set the class attribute `schema` to its "
                            "kubric.io.schema.Schema (see docs/architecture.md)")
        return
    for schema in (cls.schema, *cls.variants):
        if not isinstance(schema, Schema):
            raise TypeError(f"recipe {cls.name!r}: schema / variants must be "
                            f"kubric.io.schema.Schema objects, got {type(schema).__name__}")
    if cls.schema.name != cls.name:  # scenes name their recipe; the packer finds the schema so
        raise TypeError(f"recipe {cls.name!r} declares schema {cls.schema.name!r}: a recipe's "
                        "schema carries the recipe's name (declare its own, e.g. with "
                        "Schema.extend)")
    for schema in (cls.schema, *cls.variants):
        register_schema(schema)
    register_variants(cls.schema.name, [v.name for v in cls.variants])


def schema_of(spec: Schema | str) -> Schema:
    """The schema named ``spec`` (a recipe's, or a variant's like ``movi_a_tracks``), or the
    schema of the recipe ``spec`` names (``module:Class`` too). The built-in recipes are imported
    first. :class:`SchemaError` (one line) when there is none."""
    if isinstance(spec, Schema):
        return spec
    load_builtin()
    try:
        return get_schema(spec)
    except SchemaError as missing:
        try:
            schema = get_recipe(spec).schema
        except (ValueError, ImportError):
            schema = None
        if schema is None:
            raise missing from None
        return schema


class SceneSchemaError(SchemaError):
    """A scene directory whose schema is neither stored nor known here (one line)."""


@dataclasses.dataclass(frozen=True)
class SceneSchema:
    """The schema of one scene directory and where it came from.

    ``origin``: ``schema.json`` (stored by the writer), or the fallback for scenes written
    before scenes stored their schema: ``recipe 'NAME' (no schema.json)``. ``variants``: the
    names of further schemas over the same scenes (``--schema`` may ask for them)."""

    schema: Schema
    origin: str
    variants: tuple[str, ...] = ()

    @property
    def stored(self) -> bool:
        return self.origin == scene_dir.SCHEMA_FILE


def scene_schema(scene) -> SceneSchema:
    """The schema of scene directory ``scene`` (a local path): the one it stores
    (``schema.json``: no recipe is imported), else — a scene written before scenes stored their
    schema — that of the recipe its ``metadata.json`` names (``flags.recipe``; the built-in
    recipes are imported). :class:`SceneSchemaError` (one line) when neither gives one; a
    malformed ``schema.json`` is a :class:`SchemaError` naming it; an unreadable or misshapen
    ``metadata.json`` an :class:`~kubric.errors.InputError` / OSError."""
    doc = read_document(scene)
    if doc is not None:
        variants = doc.get("variants", [])
        return SceneSchema(document_schema(doc, scene), scene_dir.SCHEMA_FILE,
                           tuple(variants) if isinstance(variants, list) else ())
    path = pathlib.Path(scene) / scene_dir.METADATA_FILE
    meta = read_json(path)
    if not isinstance(meta, dict) or not isinstance(meta.get("flags", {}), dict):
        raise InputError(f"{str(path)!r} is not a JSON object with an object 'flags'")
    recipe = meta.get("flags", {}).get("recipe")
    if not isinstance(recipe, str) or not recipe:
        raise SceneSchemaError(f"{str(scene)!r} stores no {scene_dir.SCHEMA_FILE} and its "
                               f"{scene_dir.METADATA_FILE} names no recipe (flags.recipe): its "
                               "schema is unknown")
    try:
        schema = schema_of(recipe)
        cls = REGISTRY.get(recipe)
    except SchemaError:
        load_builtin()
        raise SceneSchemaError(
            f"{str(scene)!r} stores no {scene_dir.SCHEMA_FILE} (written before scenes stored "
            f"their schema) and its recipe {recipe!r} is not known here (recipes: "
            f"{', '.join(sorted(REGISTRY))}): its schema is unknown") from None
    variants = tuple(v.name for v in cls.variants) if cls is not None and \
        cls.schema is schema else ()
    return SceneSchema(schema, f"recipe {recipe!r} (no {scene_dir.SCHEMA_FILE})", variants)


def builtin_schemas() -> dict[str, Schema]:
    """Every schema the built-in recipes declare (their own and their variants), by name — not
    those other code registered in this process, so generated docs never depend on what ran
    before."""
    found: dict[str, Schema] = {}
    for cls in load_builtin().values():
        for schema in (cls.schema, *cls.variants):
            found[schema.name] = schema
    return dict(sorted(found.items()))


def recipe(name: str, **options: Option) -> Callable[[Callable], type[Recipe]]:
    """Register a function ``fn(seed, values: dict, out_dir)`` as a recipe named ``name``."""
    def wrap(fn):
        def generate(self, seed, out_dir):
            fn(seed, dict(self.values), out_dir)
        attrs = dict(options, generate=generate, __doc__=fn.__doc__, __module__=fn.__module__)
        return types.new_class(fn.__name__, (Recipe,), {"name": name},
                               lambda ns: ns.update(attrs))
    return wrap


def _load_module(spec: str):
    path = pathlib.Path(spec)
    if spec.endswith(".py") or path.is_file():
        if not path.is_file():
            raise OptionError(f"recipe module file {spec!r} does not exist")
        mod_name = f"_kubric_recipe_{abs(hash(str(path.resolve())))}"
        if mod_name in sys.modules:
            return sys.modules[mod_name]
        module_spec = importlib.util.spec_from_file_location(mod_name, path)
        module = importlib.util.module_from_spec(module_spec)
        sys.modules[mod_name] = module
        module_spec.loader.exec_module(module)
        return module
    try:
        return importlib.import_module(spec)
    except ModuleNotFoundError as err:
        raise OptionError(f"cannot import recipe module {spec!r}: {err}") from None


def get_recipe(spec: str) -> type[Recipe]:
    """The recipe class for ``spec``: a registered name (``movi_a``), ``module:Class`` or
    ``path/to/file.py:Class``. Raises OptionError (one line) when there is none."""
    if ":" in spec:
        module_spec, _, attr = spec.rpartition(":")
        module = _load_module(module_spec)
        obj = getattr(module, attr, None)
        if not (isinstance(obj, type) and issubclass(obj, Recipe)):
            raise OptionError(f"{spec!r}: {module_spec} has no Recipe subclass named {attr!r}")
        return obj
    load_builtin()
    if spec not in REGISTRY:
        raise OptionError(f"unknown recipe {spec!r} (recipes: {', '.join(sorted(REGISTRY))})")
    return REGISTRY[spec]


def load_builtin() -> Mapping[str, type[Recipe]]:
    """Import the built-in recipe modules; returns the built-in recipes by name — only those:
    recipes that other code registered in this process (a test, a user's module) are not listed,
    so what is documented or listed never depends on what ran before."""
    for module in BUILTIN_MODULES:
        try:
            importlib.import_module(module)
        except ModuleNotFoundError as err:
            if err.name != module:
                raise
    return {name: cls for name, cls in REGISTRY.items()
            if any(cls.__module__ == m or cls.__module__.startswith(m + ".")
                   for m in BUILTIN_MODULES)}


def recipe_spec(cls: type[Recipe]) -> str:
    """A string that :func:`get_recipe` maps back to ``cls`` in another process: the registered
    name for built-in recipes, ``path/file.py:Class`` for recipes loaded from a file or
    ``__main__``, ``module:Class`` otherwise."""
    module_name = cls.__module__
    if module_name.startswith("kubric.recipes") and REGISTRY.get(cls.name) is cls:
        return cls.name
    if module_name == "__main__" or module_name.startswith("_kubric_recipe_"):
        origin = getattr(sys.modules.get(module_name), "__file__", None)
        if origin is None:
            raise ValueError(f"recipe {cls.name!r} is defined in a module with no file")
        return f"{pathlib.Path(origin).resolve()}:{cls.__qualname__}"
    return f"{module_name}:{cls.__qualname__}"

"""The renderer protocol: what a rendering backend does, the layers it may produce, and the one place
where a recipe builds its renderer (docs/renderers.md).

A backend is a class registered in :data:`BACKENDS` (name → ``"module:Class"``; imported on first
use, so naming a backend never imports bpy or embree). It is constructed as
``Backend(scene, scratch_dir=None, **settings)`` and implements :class:`Renderer`:

* ``render(frames=None, return_layers=ALL_LAYERS)`` → ``{layer: (T, H, W, C) numpy array}`` for the
  requested frames (default: the scene's ``frame_start .. frame_end``) in the layer conventions of
  docs/conventions.md: ``rgba`` uint8 (C = 4); ``depth`` (distance to the camera centre) and ``z``
  (distance along the view axis) float32 metres, 10000 where the pixel-centre ray hits nothing;
  ``segmentation`` uint32 (0 = nothing, else the object's ``segmentation_id`` or its position in
  ``scene.assets`` + 1); ``forward_flow`` / ``backward_flow`` float32 (Δrow, Δcol) in pixels;
  ``normal`` float32 world-space unit normals; ``object_coordinates`` and ``uv`` float32 in
  [0, 1]. Every annotation layer is the value at the surface seen through the pixel centre, 0 on
  background (depth / z: 10000).
* ``settings()`` → the JSON-able dict recorded as ``metadata["renderer"]``: ``engine`` (the
  backend's name for itself) and the settings that decide its pixels.
* ``save_state(path)`` → the path written: the backend's own scene file (Blender: ``.blend``),
  for backends whose capabilities have a ``state_file_suffix``; other backends refuse in one line.
* ``capabilities``: what the backend can do (:class:`Capabilities`), declared with its row in
  :data:`BACKENDS`, so :func:`capabilities` answers without importing the backend (no bpy);
  ``layers`` is ``capabilities.layers``; ``scene``: the scene.

Recipes ask, never compare names: ``capabilities(name).photoreal``, or :func:`refusal` /
:func:`require` for what a recipe's options ask of its backend (:data:`NEEDS`); a bad combination
is one line naming the backend, the request and the backends that can.

Adding a backend = one new module with the class + one row in :data:`BACKENDS`.
"""

from __future__ import annotations

import abc
import importlib
import pathlib
from dataclasses import dataclass

import numpy as np

from kubric.core.pbr_materials import PATTERNS
from kubric.errors import UsageError
from kubric.io.layers import EXACT_LAYERS, RENDERED_LAYERS

#: the exact annotation layers (one value per pixel centre; docs/conventions.md) and every layer
#: a backend may be asked for: declared once, in kubric.io.layers
ANNOTATION_LAYERS = EXACT_LAYERS
ALL_LAYERS = RENDERED_LAYERS

#: exposure effects a backend may render into RGB (the annotation layers stay exact): motion
#: blur over a shutter, thin-lens depth of field (the camera's ``use_dof``), rolling shutter
EFFECTS = ("motion_blur", "depth_of_field", "rolling_shutter")
#: a need ``"procedural_<pattern>"``: show that ProceduralMaterial pattern in RGB
PATTERN_NEED = "procedural_"


class CapabilityError(UsageError, ValueError):
    """Something asked of a backend that it cannot do (one line: the backend, the request and
    the backends that can; exit status 2)."""


@dataclass(frozen=True)
class Capabilities:
    """What a backend can do (declared with its row in :data:`BACKENDS`).

    Attributes:
      photoreal: its RGB is path traced (shading, shadows, reflections, specular BRDFs); False:
        a preview (e.g. raycast's Lambert shading) that only makes a scene complete.
      layers: the subset of :data:`ALL_LAYERS` it can produce.
      effects: the subset of :data:`EFFECTS` it renders.
      state_file_suffix: ``save_state`` writes its scene file with this suffix (``".blend"``);
        None: it saves no state.
      characters: it renders skinned characters (:class:`kubric.core.characters.Character`).
      quality_profiles: it takes the recipes' RGB quality settings (``samples_per_pixel``,
        ``use_denoising``, ``adaptive_sampling``, ...; docs/render-cost.md).
      lenses: it renders a camera with a lens model (``PerspectiveCamera.lens``,
        :mod:`kubric.core.lenses`) exactly: RGB and every layer through each pixel's lens ray.
      procedural_patterns: the :class:`~kubric.core.pbr_materials.ProceduralMaterial` patterns
        whose texture its RGB shows (a subset of :data:`PATTERNS`); a scene with another
        pattern is refused in one line.
    """

    photoreal: bool = False
    layers: tuple[str, ...] = ALL_LAYERS
    effects: frozenset[str] = frozenset()
    state_file_suffix: str | None = None
    characters: bool = False
    quality_profiles: bool = False
    lenses: bool = False
    procedural_patterns: tuple[str, ...] = ()

    def __post_init__(self):
        object.__setattr__(self, "layers", tuple(self.layers))
        object.__setattr__(self, "procedural_patterns", tuple(self.procedural_patterns))
        object.__setattr__(self, "effects", frozenset(self.effects))
        for what, given, allowed in (("layers", self.layers, ALL_LAYERS),
                                     ("effects", self.effects, EFFECTS),
                                     ("procedural_patterns", self.procedural_patterns,
                                      PATTERNS)):
            unknown = sorted(set(given) - set(allowed))
            if unknown:
                raise ValueError(f"Capabilities: unknown {what} {unknown}; allowed: "
                                 f"{list(allowed)}")

    @property
    def can_save_state(self) -> bool:
        return self.state_file_suffix is not None

    def has(self, need: str) -> bool:
        """Whether it can do ``need``, one of :data:`NEEDS`."""
        if need not in NEEDS:
            raise ValueError(f"unknown renderer capability {need!r}; allowed: {list(NEEDS)}")
        if need in EFFECTS:
            return need in self.effects
        if need in ALL_LAYERS:
            return need in self.layers
        if need.startswith(PATTERN_NEED):
            return need[len(PATTERN_NEED):] in self.procedural_patterns
        return bool(self.can_save_state if need == "save_state" else getattr(self, need))


#: what a recipe may ask of its backend → the words of a refusal ("renderer=X cannot ...")
NEEDS = {
    "photoreal": "render photoreal RGB",
    "characters": "render skinned characters",
    "save_state": "save its state as a scene file",
    "quality_profiles": "take the RGB quality settings (samples, denoising)",
    "lenses": "render through a lens model (distortion)",
    **{effect: f"render {effect.replace('_', ' ')}" for effect in EFFECTS},
    **{layer: f"make the {layer} layer" for layer in ALL_LAYERS},
    **{PATTERN_NEED + p: f"render {p} procedural materials" for p in PATTERNS},
}


@dataclass(frozen=True)
class Backend:
    """One row of :data:`BACKENDS`: where the class is (``"module:Class"``, imported on first
    use) and what it can do (read without importing it)."""

    path: str
    capabilities: Capabilities


#: name → Backend of every backend (the recipes' ``renderer`` option values)
BACKENDS = {
    "blender": Backend("kubric.renderer.blender:Blender", Capabilities(
        photoreal=True, effects={"motion_blur", "depth_of_field", "rolling_shutter"},
        state_file_suffix=".blend",
        characters=True, quality_profiles=True, lenses=True, procedural_patterns=PATTERNS)),
    "raycast": Backend("kubric.renderer.raycast:Raycast", Capabilities(
        photoreal=False, lenses=True, effects={"rolling_shutter"}, characters=True,
        procedural_patterns=("checker", "brick", "wave"))),
}


def capabilities(name: str) -> Capabilities:
    """What the backend ``name`` can do, without importing it."""
    if name not in BACKENDS:
        raise ValueError(f"unknown renderer {name!r}; allowed: {sorted(BACKENDS)}")
    return BACKENDS[name].capabilities


def able(needs) -> list[str]:
    """The backends that can do every one of ``needs`` (names of :data:`NEEDS`)."""
    return [name for name, row in BACKENDS.items() if all(row.capabilities.has(n) for n in needs)]


def refusal(name: str, requests: dict[str, str], who: str) -> str | None:
    """One line when backend ``name`` cannot do what ``requests`` (need → what asked for it,
    e.g. ``{"motion_blur": "max_motion_blur=2.0"}``) asks, naming the backends that can; else
    None."""
    missing = {need: asked for need, asked in requests.items()
               if not capabilities(name).has(need)}
    return _refusal_line(name, missing, who) if missing else None


def _refusal_line(name: str, missing: dict[str, str], who: str) -> str:
    what = "; ".join(f"{NEEDS[need]} ({asked})" for need, asked in missing.items())
    can = able(missing)
    return (f"{who}: renderer={name} cannot {what}; backends that can: "
            f"{', '.join(can) if can else 'none'}")


def require(name: str, requests: dict[str, str], who: str) -> None:
    """:func:`refusal` as a :class:`CapabilityError`."""
    message = refusal(name, requests, who)
    if message:
        raise CapabilityError(message)


def name_of(cls: type) -> str | None:
    """The name the backend class ``cls`` is registered under in BACKENDS (None: no row)."""
    path = f"{cls.__module__}:{cls.__qualname__}"
    return next((name for name, row in BACKENDS.items() if row.path == path), None)


class _Declared:
    """``Backend.capabilities``: the Capabilities of the class's row in BACKENDS (the defaults
    for a class no row names)."""

    def __get__(self, obj, cls):
        name = name_of(cls)
        return Capabilities() if name is None else BACKENDS[name].capabilities


class _Layers:
    def __get__(self, obj, cls):
        return cls.capabilities.layers


class Renderer(abc.ABC):
    """The protocol every rendering backend implements (see module doc)."""

    #: what this backend can do (:class:`Capabilities`, from its row in BACKENDS)
    capabilities = _Declared()
    #: the layers this backend can produce (``capabilities.layers``)
    layers = _Layers()
    #: the scene it renders (a :class:`kubric.core.scene.Scene`), set by the constructor
    scene = None

    @abc.abstractmethod
    def render(self, frames=None, return_layers=ALL_LAYERS) -> dict[str, np.ndarray]:
        """Render ``frames`` → ``{layer: (T, H, W, C) array}`` for every layer of
        ``return_layers``."""

    @abc.abstractmethod
    def settings(self) -> dict:
        """``metadata["renderer"]``: ``engine`` and the settings that decide the pixels."""

    def save_state(self, path) -> pathlib.Path:
        """Write the backend's scene file to ``path`` (its suffix is
        ``capabilities.state_file_suffix``); a backend without one refuses in one line."""
        self._require({"save_state": f"save_state({str(path)!r})"},
                      f"{type(self).__name__}.save_state")
        raise NotImplementedError(f"{type(self).__name__} declares state_file_suffix but does "
                                  "not implement save_state")

    def require_effects(self, requests: dict[str, str]) -> None:
        """One line (:class:`CapabilityError`) for each effect of ``requests`` (effect → the
        setting that asks for it) this backend does not render; a backend calls it for the
        effects its settings and scene ask for instead of ignoring them."""
        self._require({e: asked for e, asked in requests.items() if asked}, type(self).__name__)

    def _require(self, requests: dict[str, str], who: str) -> None:
        missing = {need: asked for need, asked in requests.items()
                   if not self.capabilities.has(need)}
        if missing:
            raise CapabilityError(_refusal_line(name_of(type(self)) or type(self).__name__,
                                                missing, who))

    def check_request(self, frames, return_layers) -> tuple[list[int], tuple[str, ...]]:
        """The validated (frames, layers) of a render call: frames default to the scene's range,
        must be integers ≥ 0 and not empty; every layer must be one of :attr:`layers`."""
        who = f"{type(self).__name__}.render"
        frames = list(self.scene.frames if frames is None else frames)
        if not frames:
            raise ValueError(f"{who}: frames is empty")
        for f in frames:
            if isinstance(f, bool) or not isinstance(f, (int, np.integer)):
                raise TypeError(f"{who}: frames must be integers, got {f!r}")
        frames = [int(f) for f in frames]
        if min(frames) < 0:
            raise ValueError(f"{who}: renders frames ≥ 0 only, got {min(frames)}")
        if isinstance(return_layers, str):
            raise TypeError(f"{who}: return_layers must be a sequence of layer names, got the "
                            f"string {return_layers!r}")
        wanted = tuple(return_layers)
        unknown = sorted(set(wanted) - set(self.layers))
        if unknown:
            raise ValueError(f"{who}: unknown layers {unknown}; allowed: {list(self.layers)}")
        return frames, wanted


def backend(name: str) -> type:
    """The backend class registered as ``name`` (imports its module)."""
    capabilities(name)  # an unknown name: one line naming the allowed ones
    module, cls = BACKENDS[name].path.split(":")
    return getattr(importlib.import_module(module), cls)


def create(name: str, scene, scratch_dir=None, **settings) -> Renderer:
    """Build the renderer ``name`` of :data:`BACKENDS` for ``scene`` with its keyword
    ``settings`` (each backend documents and checks its own)."""
    return backend(name)(scene, scratch_dir, **settings)


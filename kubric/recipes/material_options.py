"""Random PBR materials for a recipe's objects and floor: ``material_source=procedural|DIR``,
``material_probability``, ``material_patterns`` (MOVi-C–F, toybox; docs/materials.md).

After the scene is built, every foreground physical object (skinned characters and articulated
models keep theirs) and then the floor get, each with probability ``material_probability``, a
material drawn from the source with an rng derived from the seed
(:func:`kubric.assets.material_source.derived_rng`), so the rest of the scene is the scene made
without the option. Recorded as data: each instance's ``material`` in ``metadata.json``
(:meth:`describe` of the drawn material, or ``{"source": "recipe"}`` for an object that kept the
recipe's own) and ``metadata.floor_material``. A floor whose recipe material was invisible to
non-camera rays (the HDRI domes of MOVi-C–F and toybox) keeps that (``indirect_visibility``
False): it is lit and shadowed for the camera but neither blocks the HDRI light nor shows in
reflections, as before; an image set's licence and attribution are in
``metadata.material_licenses``. Without ``material_source`` none of these fields exist and the
options are left out of ``flags``.
"""

from __future__ import annotations

from kubric.assets.material_source import PROCEDURAL, derived_rng, open_material_source
from kubric.core.pbr_materials import PATTERNS
from kubric.errors import InputError
from kubric.pipeline import Option, OptionError
from kubric.renderer.base import PATTERN_NEED


def material_location(value):
    """``procedural`` or an existing folder (a material source)."""
    import pathlib

    text = str(value).strip()
    if text == PROCEDURAL:
        return PROCEDURAL
    try:
        path = pathlib.Path(text).expanduser()
        found = path.is_dir()
    except (OSError, ValueError, RuntimeError):  # a name too long, a NUL byte, no home
        found = False
    if not found:
        raise ValueError(f"expected {PROCEDURAL!r} or an existing material source folder, got "
                         f"{text!r}")
    return path


material_location.allowed = (f"{PROCEDURAL} or an existing material source folder (with "
                             "materials.json)")
material_location.__name__ = "procedural|path"


def pattern_list(value) -> tuple[str, ...]:
    names = tuple(v.strip() for v in (value.split(",") if isinstance(value, str) else value)
                  if str(v).strip())
    unknown = [n for n in names if n not in PATTERNS]
    if not names or unknown:
        raise ValueError(f"expected comma-separated patterns of {list(PATTERNS)}, got {value!r}")
    return names


pattern_list.allowed = f"comma-separated names of {', '.join(PATTERNS)}"
pattern_list.__name__ = "names"


class MaterialOptions:
    """Options and the step that gives objects and the floor random PBR materials."""

    material_source = Option(None, "random PBR materials for objects and floor: "
                             f"'{PROCEDURAL}' (built in, no download) or a material source "
                             "folder (kubric assets materials); none = the recipe's own",
                             type=material_location)
    material_probability = Option(1.0, "with material_source: the chance that each object and "
                                  "the floor get a random material", low=0.0, high=1.0)
    material_patterns = Option(PATTERNS, f"with material_source={PROCEDURAL}: the patterns "
                               "drawn from (comma-separated)", type=pattern_list)

    MATERIAL_OPTIONS = ("material_source", "material_probability", "material_patterns")

    def material_flags(self, out: dict) -> dict:
        """``flags`` without the material options while ``material_source`` is none."""
        if self.material_source is None:
            for name in self.MATERIAL_OPTIONS:
                out.pop(name, None)
        return out

    def material_requests(self) -> dict[str, str]:
        """What the procedural patterns ask of the renderer (``renderer_requests``)."""
        if self.material_source != PROCEDURAL:
            return {}
        asked = f"material_patterns={','.join(self.material_patterns)}"
        return {PATTERN_NEED + p: asked for p in self.material_patterns}

    def open_materials(self):
        """The material source (None without the option); a bad folder is an OptionError."""
        if self.material_source is None:
            return None
        try:
            return open_material_source(self.material_source, self.material_patterns)
        except InputError as err:
            raise OptionError(f"{self.name}: option material_source: {err}") from None

    def apply_materials(self, scene, seed: int, floor=None) -> None:
        """Draw the random materials (module doc); ``floor``: the floor object or None."""
        source = self.open_materials()
        if source is None:
            return
        import kubric as kb
        from kubric.core.characters import Character

        rng = derived_rng(seed)
        licenses = {}

        def draw(obj, kind):
            if rng.uniform() >= self.material_probability:
                return {"source": "recipe"}
            material = source.sample(rng, kind)
            # a dome the recipe kept out of the lighting (HDRI scenes) stays out of it
            material.indirect_visibility = bool(getattr(obj.material, "indirect_visibility",
                                                        True))
            obj.material = material
            described = material.describe()
            if described.get("license"):
                licenses[described["material_id"]] = {
                    "license": described["license"], "attribution": described["attribution"],
                    "source_url": described["source_url"]}
            return described

        for obj in scene.foreground_assets:
            if isinstance(obj, kb.PhysicalObject) and not isinstance(obj, Character) \
                    and not {"urdf", "articulated_link"} & set(obj.metadata):
                obj.metadata = {**obj.metadata, "material": draw(obj, "object")}
        scene.metadata["floor_material"] = draw(floor, "floor") if floor is not None else None
        scene.metadata["material_source"] = getattr(source, "name", str(self.material_source))
        scene.metadata["material_licenses"] = dict(sorted(licenses.items()))

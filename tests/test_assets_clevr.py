"""The CLEVR facts live in one module (kubric.assets.clevr) and every user reads them from there."""

import pathlib
import re

import numpy as np
import pytest

import kubric
from kubric import randomness
from kubric.assets import clevr
from kubric.core import lights as core_lights

PACKAGE = pathlib.Path(kubric.__file__).parent


def test_facts_are_consistent():
    assert len(clevr.COLORS) == 8 and list(clevr.COLORS) == sorted(clevr.COLORS)
    assert set(clevr.COLORS) == set(clevr.COLORS_RGB255)
    for name, rgb in clevr.COLORS_RGB255.items():
        assert np.allclose(clevr.COLORS[name].rgb, np.array(rgb) / 255.0)
    assert list(clevr.SIZES) == ["small", "large"] and clevr.SIZES["small"] < clevr.SIZES["large"]
    assert list(clevr.MATERIALS) == ["metal", "rubber"]
    assert clevr.KUBASIC_SHAPES[:3] == clevr.SHAPES and len(set(clevr.KUBASIC_SHAPES)) == 11
    for name, class_name, kwargs, position in clevr.LIGHTS:
        getattr(core_lights, class_name)(name=name, **kwargs)  # known class, known properties
        assert len(position) == 3
    with pytest.raises(TypeError):
        clevr.SIZES["small"] = 1.0  # read-only: a user cannot change the facts for everyone


def test_recipes_and_schema_read_the_facts():
    from kubric.asset_tools import kubasic
    from kubric.recipes import complex_brdf, movi_schema

    features = {f.name: f for f in movi_schema.MOVI_A.features}
    assert features["instances/shape_label"].names == clevr.SHAPES
    assert features["instances/size_label"].names == tuple(clevr.SIZES)
    assert features["instances/color_label"].names == tuple(clevr.COLORS)
    assert features["instances/material_label"].names == tuple(clevr.MATERIALS)
    b = {f.name: f for f in movi_schema.MOVI_B.features}
    assert b["instances/shape_label"].names == clevr.KUBASIC_SHAPES
    assert list(kubasic.SHAPES) == [*clevr.KUBASIC_SHAPES, "dome"]
    assert complex_brdf.MATERIALS["metal"] == dict(clevr.MATERIALS["metal"].bsdf)
    assert sorted(complex_brdf.SHAPES) == sorted(clevr.KUBASIC_SHAPES)


def test_klevr_checks_shapes_against_kubasic():
    from kubric.pipeline import OptionError, get_recipe

    with pytest.raises(OptionError, match=re.escape(str(sorted(clevr.KUBASIC_SHAPES)))):
        get_recipe("klevr").from_assignments(["shapes=cube,pyramid"]).check()


def test_sampling_uses_the_facts():
    rng = np.random.RandomState(3)
    for _ in range(20):
        label, size = randomness.sample_sizes("clevr", rng)
        assert size == clevr.SIZES[label]
        assert clevr.SIZES["small"] <= randomness.sample_sizes("uniform", rng)[1] \
            <= clevr.SIZES["large"]
        label, color = randomness.sample_color("clevr", rng)
        assert color == clevr.COLORS[label]
    lights = kubric.assets.utils.get_clevr_lights(light_jitter=0.0, rng=rng)
    assert [(light.name, type(light).__name__) for light in lights] == \
        [(name, cls) for name, cls, _, _ in clevr.LIGHTS]
    assert np.allclose([light.position for light in lights], [p for *_, p in clevr.LIGHTS])


def _distinctive_literals():
    """Regexes for the numbers only CLEVR uses: colour triplets, lamp and camera positions."""
    pats = [r"\b" + r",\s*".join(map(str, rgb)) + r"\b" for rgb in clevr.COLORS_RGB255.values()]
    numbers = [p[0] for *_, p in clevr.LIGHTS] + [clevr.CAMERA_POSITION[0]]
    return pats + [re.escape(repr(x)) for x in numbers]


def test_no_other_module_restates_the_facts():
    pats = _distinctive_literals()
    assert any(re.search(p, (PACKAGE / "assets" / "clevr.py").read_text()) for p in pats)
    offenders = []
    for path in sorted(PACKAGE.rglob("*.py")):
        if path == PACKAGE / "assets" / "clevr.py":
            continue
        text = path.read_text()
        offenders += [f"{path.relative_to(PACKAGE)}: {p}" for p in pats if re.search(p, text)]
    assert offenders == []


def test_docs_list_the_facts_as_the_module_defines_them():
    page = (PACKAGE.parent / "docs" / "assets.md").read_text()
    for name, rgb in clevr.COLORS_RGB255.items():
        assert f"| {name} | {', '.join(map(str, rgb))} |" in page, name
    for name, m in clevr.MATERIALS.items():
        assert re.search(rf"\| {name} \| [^|]+ \| {m.friction:g} \| {m.restitution:g} \| "
                         rf"{m.density:g} \|", page), name
        row = page[page.index(f"| {name} |"):].splitlines()[0]
        for key, value in m.bsdf.items():
            label = "IOR" if key == "ior" else key
            assert f"{label} {value:g}" in row, (name, key)
    for label, scale in clevr.SIZES.items():
        assert f"`{label}` {scale:g}" in page, label

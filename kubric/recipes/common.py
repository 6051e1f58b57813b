"""Option checks and asset-source opening shared by every recipe family (MOVi, multi-view)."""

from __future__ import annotations

from kubric.pipeline import OptionError


def open_existing_source(path, what: str):
    """The :class:`~kubric.AssetSource` at ``path`` (option ``what``); one line if it is empty."""
    import kubric as kb

    source = kb.AssetSource(path)
    if not len(source):
        raise OptionError(f"{what} {str(path)!r} holds no assets")
    return source


def kubasic_sources(kubasic_source) -> dict:
    """``{"kubasic": source}``: the folder given by the option, else the locally built KuBasic."""
    from kubric import assets

    if kubasic_source is not None:
        return {"kubasic": open_existing_source(kubasic_source, "kubasic_source")}
    return {"kubasic": assets.ensure_kubasic()}


def check_source_options(recipe, names=None) -> None:
    """Every asset-source option (``*_source``, plus ``names``) that is set names a folder with
    ``manifest.json`` (or that file); raises OptionError (one line) otherwise."""
    for name, value in recipe.values.items():
        if (name.endswith("_source") or name in (names or ())) and value is not None:
            manifest = value / "manifest.json" if value.is_dir() else value
            if not manifest.is_file() or manifest.name != "manifest.json":
                raise OptionError(f"{recipe.name}: option {name}={str(value)!r} is not an asset "
                                  "source (a folder with manifest.json)")


def min_max_pairs(recipe) -> list[tuple[str, str]]:
    """(``min_X``, ``max_X``) option pairs of a recipe, which must be ordered."""
    return [(a, a.replace("min_", "max_", 1)) for a in recipe.options if a.startswith("min_")
            and a.replace("min_", "max_", 1) in recipe.options]


def check_min_max(recipe) -> None:
    """Every ``min_X`` ≤ ``max_X``; raises OptionError (one line) otherwise."""
    for low, high in min_max_pairs(recipe):
        if recipe.values[low] > recipe.values[high]:
            raise OptionError(f"{recipe.name}: option {low}={recipe.values[low]} must be ≤ "
                              f"{high}={recipe.values[high]}")

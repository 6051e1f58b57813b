"""Worker contract (recipes, options, atomic scene directories) and the local runner."""

from kubric.pipeline.options import Option, OptionError, float_range, resolution
from kubric.pipeline.recipe import REGISTRY, Recipe, get_recipe, recipe, recipe_spec
from kubric.pipeline.worker import SceneResult, is_complete, run_scene, scene_name

__all__ = [
    "Option", "OptionError", "float_range", "resolution", "REGISTRY", "Recipe", "get_recipe",
    "recipe", "recipe_spec", "SceneResult", "is_complete", "run_scene", "scene_name",
]

"""Kubric: a scalable synthetic-data generator (scene model + PyBullet + Blender Cycles).

``import kubric as kb`` is fast and imports no engine: names below that live in heavier modules
(``kb.renderer.Blender``, ``kb.simulator.PyBullet``, ``kb.AssetSource``, file writers, ...) are
loaded on first access.
"""

import importlib

from kubric.core import *  # noqa: F403
from kubric.core import __all__ as _core_all

__version__ = "0.1.0"

#: name at ``kb.`` → module that defines it (imported on first access).
_LAZY = {
    "renderer": "kubric.renderer",
    "simulator": "kubric.simulator",
    "file_io": "kubric.file_io",
    "randomness": "kubric.randomness",
    "post_processing": "kubric.post_processing",
    "utils": "kubric.utils",
    "assets": "kubric.assets",
}
_LAZY_NAMES = {
    "kubric.assets": ["AssetSource"],
    "kubric.randomness": [
        "random_hue_color", "random_rotation", "rotation_sampler", "position_sampler",
        "bottom_sampler", "resample_while", "move_until_no_overlap",
        "sample_point_in_half_sphere_shell",
    ],
    "kubric.post_processing": ["compute_visibility", "compute_bboxes", "adjust_segmentation_idxs"],
    "kubric.file_io": [
        "as_path", "write_pkl", "write_json", "write_png", "write_palette_png",
        "write_scaled_png", "write_tiff", "write_image_dict", "read_png", "read_tiff",
        "read_json", "read_pkl", "read_palette_png", "read_scaled_png", "read_image_dict",
        "read_layer", "read_segmentation",
    ],
    "kubric.utils": [
        "ArgumentParser", "done", "get_camera_info", "get_instance_info", "get_scene_metadata",
        "log_my_flags", "process_collisions", "setup", "setup_directories", "setup_logging",
    ],
}
for _module, _names in _LAZY_NAMES.items():
    for _name in _names:
        _LAZY[_name] = _module


def __getattr__(name):
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'kubric' has no attribute {name!r}")
    mod = importlib.import_module(module)
    value = mod if module.rsplit(".", 1)[-1] == name else getattr(mod, name)
    globals()[name] = value
    return value


def __dir__():
    return sorted(set(globals()) | set(_LAZY))


__all__ = list(_core_all) + sorted(_LAZY)

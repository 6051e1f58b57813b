"""Forbids importing bpy — loaded by ``pytest --no-blender`` (see tests/conftest.py) in the test
process and, through ``PYTHONPATH``, in every subprocess a test starts. A test that imports bpy
without the ``blender`` marker therefore fails with a message saying so. Locating the package
(``importlib.util.find_spec("bpy")``, e.g. for the HDRIs it ships) still works."""

import importlib.abc
import importlib.machinery
import sys

MESSAGE = ("bpy is blocked by pytest --no-blender: mark the test that imports it with "
           "@pytest.mark.blender")


class _RaiseOnExec(importlib.abc.Loader):
    def create_module(self, spec):
        return None

    def exec_module(self, module):
        raise RuntimeError(MESSAGE)


class BlockBpy(importlib.abc.MetaPathFinder):
    """Finds the real bpy (so its location is known) but gives it a loader that raises."""

    def find_spec(self, name, path=None, target=None):
        if name != "bpy":
            return None
        spec = importlib.machinery.PathFinder.find_spec(name, path)
        if spec is not None:
            spec.loader = _RaiseOnExec()
        return spec


if not any(type(f).__name__ == "BlockBpy" for f in sys.meta_path):
    sys.meta_path.insert(0, BlockBpy())

"""Physics simulation views of the scene model.

``import kubric.simulator`` is cheap: the PyBullet view (and pybullet itself) is loaded on first
access of ``kubric.simulator.PyBullet`` (or ``import kubric.simulator.pybullet``).
"""

import importlib

__all__ = ["PyBullet"]


def __getattr__(name):
    if name == "PyBullet":
        value = importlib.import_module("kubric.simulator.pybullet").PyBullet
        globals()[name] = value
        return value
    raise AttributeError(f"module 'kubric.simulator' has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(__all__))

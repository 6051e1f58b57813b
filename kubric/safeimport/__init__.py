"""Upstream Kubric's module path for importing Blender: ``from kubric.safeimport.bpy import bpy``.

Nothing is imported here; ``kubric.safeimport.bpy`` imports ``bpy`` when it is itself imported.
"""

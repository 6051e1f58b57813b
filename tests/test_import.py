"""`import kubric` stays light: no engine (its time is measured by benchmarks/bench_import.py)."""

import subprocess
import sys


def test_import_kubric_loads_no_engine():
    code = ("import kubric as kb, sys; "
            "heavy = {'bpy', 'pybullet', 'trimesh', 'torch', 'tensorflow'} & set(sys.modules); "
            "print(sorted(heavy))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


def test_lazy_names_resolve():
    import kubric as kb
    assert callable(kb.move_until_no_overlap)
    assert "renderer" in dir(kb)


def test_built_in_recipes_load_no_mesh_library():
    """Every `kubric worker` imports the built-in recipes (to find its recipe by name): trimesh
    and scipy (~0.5 s) come with the layers that cast rays, not with the registry."""
    code = ("import kubric.recipes, sys; "
            "print(sorted({'bpy', 'pybullet', 'trimesh', 'scipy'} & {m.split('.')[0] "
            "for m in sys.modules}))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"

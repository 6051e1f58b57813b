"""`import kubric` stays light: no engine, fast."""

import subprocess
import sys


def test_import_kubric_loads_no_engine_and_is_fast():
    code = ("import time; t = time.perf_counter(); import kubric as kb, sys; "
            "dt = time.perf_counter() - t; "
            "assert 'bpy' not in sys.modules and 'pybullet' not in sys.modules, 'engine imported'; "
            "assert 'trimesh' not in sys.modules; print(dt)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert float(out.stdout.strip()) < 0.5


def test_lazy_names_resolve():
    import kubric as kb
    assert callable(kb.move_until_no_overlap)
    assert "renderer" in dir(kb)

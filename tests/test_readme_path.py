"""The README's "first hour" runs top to bottom, as written, in a fresh folder — at tiny settings,
so that the README cannot drift from what works.

Each line of the block between ``<!-- first-hour: begin -->`` and ``end`` is run in order with
these substitutions only: ``make demo`` (install + six scenes) becomes the demo's first MOVi-A
scene generated into ``demo_output/movi_a``; activating the venv and ``pip install`` are this
environment's (the datasets extra is checked importable); every ``generate`` renders 3 scenes
with the raycast backend at 32², 3 frames (the README's ``resolution`` / ``quality`` replaced);
``kubric view`` listens on a free port, is asked for its scene list and stopped.
"""

import importlib.util
import json
import pathlib
import shlex
import subprocess
import sys
import urllib.request

ROOT = pathlib.Path(__file__).resolve().parents[1]
TINY = ["--set", "renderer=raycast", "--set", "resolution=32", "--set", "frame_end=3"]
SCENES = 3


def readme_steps() -> list[list[str]]:
    text = (ROOT / "README.md").read_text()
    block = text.split("<!-- first-hour: begin -->", 1)[1].split("<!-- first-hour: end -->")[0]
    body = block.split("```bash\n", 1)[1].split("```", 1)[0]
    return [argv for argv in (shlex.split(line, comments=True) for line in body.splitlines())
            if argv]


def tiny_generate(argv: list[str]) -> list[str]:
    out, i = [], 0
    while i < len(argv):
        if argv[i] == "--set" and argv[i + 1].split("=")[0] in ("resolution", "quality"):
            i += 2
            continue
        out.append(str(SCENES) if i and argv[i - 1] == "--scenes" else argv[i])
        i += 1
    return out + TINY


def kubric(argv, cwd):
    return subprocess.run([sys.executable, "-m", "kubric", *argv], cwd=cwd, capture_output=True,
                          text=True, timeout=600)


def view_lists_scenes(argv, cwd) -> list[dict]:
    proc = subprocess.Popen([sys.executable, "-m", "kubric", *argv, "--port", "0"], cwd=cwd,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        line = proc.stdout.readline()
        assert "serving" in line, line + proc.stderr.read()
        url = line.split(" at ", 1)[1].split()[0]
        with urllib.request.urlopen(url + "api/scenes", timeout=60) as response:
            return json.loads(response.read())["scenes"]
    finally:
        proc.terminate()
        proc.wait(timeout=30)


def test_the_first_hour_runs_top_to_bottom(tmp_path):
    steps = readme_steps()
    assert [s[:2] for s in steps][:3] == [["make", "demo"], ["source", ".venv-demo/bin/activate"],
                                          ["kubric", "inspect"]]
    ran = []
    for argv in steps:
        if argv == ["make", "demo"]:
            proc = kubric(["generate", "movi_a", "--out", "demo_output/movi_a", "--scenes", "1",
                           "--no-progress", *TINY], tmp_path)
        elif argv[0] == "source":
            continue
        elif argv[:2] == ["pip", "install"]:
            assert "datasets" in argv[-1]
            assert importlib.util.find_spec("tensorflow_datasets") is not None
            continue
        elif argv[:2] == ["kubric", "view"]:
            listed = view_lists_scenes(argv[1:], tmp_path)
            assert [s["name"] for s in listed] == [f"scene_{i:08d}" for i in range(SCENES)]
            ran.append("view")
            continue
        elif argv[:2] == ["kubric", "generate"]:
            proc = kubric(tiny_generate(argv[1:]), tmp_path)
        elif argv[0] == "kubric":
            proc = kubric(argv[1:], tmp_path)
        elif argv[:2] == ["python", "-c"]:
            proc = subprocess.run([sys.executable, "-c", argv[2]], cwd=tmp_path,
                                  capture_output=True, text=True, timeout=300)
        else:
            raise AssertionError(f"the test does not know how to run {argv}")
        assert proc.returncode == 0, f"{argv}\n{proc.stdout}\n{proc.stderr}"
        ran.append(argv[1] if argv[0] in ("kubric", "make") else argv[0])
        if argv[:2] == ["python", "-c"]:
            assert proc.stdout.strip() == "(3, 32, 32, 3)"  # video of a train example
    assert ran == ["demo", "inspect", "generate", "view", "pack", "python", "export"]
    assert (tmp_path / "scene_00000000_contact_sheet.png").is_file()
    coco = json.loads((tmp_path / "movi_a_coco.json").read_text())
    assert len(coco["images"]) == SCENES * 3

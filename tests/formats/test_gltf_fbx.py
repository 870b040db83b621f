"""glTF 2.0 import and export, FBX import: exact round trips, foreign files with known answers,
the animation choice, hostile files, the command line."""

from __future__ import annotations

import json
import math
import random
import subprocess
import sys

import numpy as np
import pytest

from conftest import DATA, SHARED
from gltf_builder import GltfBuilder, trs_matrix as _matrix
from mocodec import load, save
from mocodec.errors import FormatError, MocodecError
from mocodec.formats.gltfwrite import to_gltf_bytes

pytest.importorskip("pygltflib")

FORMATS = DATA.parent / "formats"
FBX_DATA = FORMATS / "fbx"


def _joint_error_cm(a, b) -> float:
    return float(np.abs(a.positions_m() - b.positions_m()).max() * 100.0)


@pytest.mark.parametrize("clip", ["07_03.bvh", "07_03.amc"])
@pytest.mark.parametrize("ext", [".glb", ".gltf"])
def test_round_trip_keeps_the_skeleton_layout_and_every_pose(clip, ext, tmp_path):
    motion = load(DATA / clip)
    save(motion, tmp_path / f"walk{ext}")
    back = load(tmp_path / f"walk{ext}")
    assert back.skeleton.difference(motion.skeleton) is None  # channels, orders, ASF axes, limits
    assert back.num_frames == motion.num_frames and back.fps == motion.fps
    assert _joint_error_cm(motion, back) < 1e-4
    save(back, tmp_path / "again.bvh")
    assert _joint_error_cm(motion, load(tmp_path / "again.bvh")) < 1e-4


def test_the_javascript_fixtures_are_what_the_writer_makes():
    sys.path.insert(0, str(DATA.parent / "js"))
    try:
        from make_fixtures import fixture, mannequin_fixture
    finally:
        sys.path.pop(0)
    for name, (glb, expected) in (("walk", fixture()), ("walk_mannequin", mannequin_fixture())):
        assert (FORMATS / f"{name}.glb").read_bytes() == glb, "run tests/js/make_fixtures.py"
        assert (FORMATS / f"{name}.glb.json").read_text() == expected, "run tests/js/make_fixtures.py"


@pytest.mark.parametrize("ext", [".glb", ".gltf"])
def test_a_file_with_the_mannequin_reads_back_the_same_motion(walk_bvh, ext, tmp_path):
    """The mesh is one skinned body on a node of its own: readers of the skeleton (ours) see the
    same motion, and a 57-joint body adds under 300 KB to a .glb."""
    import pygltflib

    clip = walk_bvh[:60]
    save(clip, tmp_path / f"body{ext}", mesh="mannequin")
    back = load(tmp_path / f"body{ext}")
    assert back.skeleton.difference(clip.skeleton) is None and _joint_error_cm(clip, back) < 1e-4
    gltf = pygltflib.GLTF2().load(str(tmp_path / f"body{ext}"))
    (node,) = [n for n in gltf.nodes if n.mesh is not None]
    assert node.skin == 0 and gltf.nodes.index(node) in gltf.scenes[0].nodes
    attributes = gltf.meshes[0].primitives[0].attributes
    assert attributes.JOINTS_0 is not None and attributes.WEIGHTS_0 is not None
    if ext == ".glb":
        added = len(to_gltf_bytes(clip, True, mesh="mannequin")) - len(to_gltf_bytes(clip, True))
        assert len(clip.skeleton) >= 57 and added < 300_000


def test_convert_writes_the_mannequin_to_gltf_only(tmp_path, capsys):
    from mocodec.cli import main

    assert main(["convert", str(DATA / "07_03.amc"), str(tmp_path / "walk.glb"), "--mesh", "mannequin"]) == 0
    assert main(["convert", str(DATA / "07_03.amc"), str(tmp_path / "walk.bvh"), "--mesh", "mannequin"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "a mesh is written to .gltf or .glb only" in err[0]
    assert not (tmp_path / "walk.bvh").exists()


def test_the_same_motion_gives_the_same_bytes(walk_bvh):
    assert to_gltf_bytes(walk_bvh, binary=True) == to_gltf_bytes(walk_bvh, binary=True)


# ----- foreign files: built here by hand, read against matrices composed here -----------------


def _axis_quat_xyzw(axis, degrees) -> list[float]:
    half = math.radians(degrees) / 2
    return [*(math.sin(half) * np.asarray(axis, float)), math.cos(half)]


def _rig(tmp_path, scale=(0.01, 0.01, 0.01)):
    """A Z-up armature at 1/100 scale (as exporters write centimetre rigs), a hip that moves
    (LINEAR) and turns (STEP), a spine with a rest rotation, a head as the bone tip."""
    g = GltfBuilder()
    g.doc["nodes"] = [
        {"name": "Armature", "children": [1], "rotation": _axis_quat_xyzw((1, 0, 0), -90), "scale": list(scale)},
        {"name": "hips", "children": [2], "translation": [0, 0, 100]},
        {"name": "spine", "children": [3], "translation": [0, 20, 0], "rotation": _axis_quat_xyzw((0, 0, 1), 30)},
        {"name": "head", "translation": [0, 15, 0]},
    ]
    g.doc["skins"] = [{"joints": [1, 2, 3]}]
    g.doc["scenes"], g.doc["scene"] = [{"nodes": [0]}], 0
    hips_at = [[0, 0, 100], [50, 0, 100], [50, 40, 90]]
    turns = [_axis_quat_xyzw((0, 1, 0), 0), _axis_quat_xyzw((0, 1, 0), 90), _axis_quat_xyzw((0, 1, 0), 45)]
    g.animation(
        "walk",
        [(1, "translation", [0, 0.5, 1.0], hips_at, "LINEAR"), (1, "rotation", [0, 0.5, 1.0], turns, "STEP")],
    )
    g.animation("wave", [(2, "rotation", [0, 1.0], [_axis_quat_xyzw((1, 0, 0), 0), turns[1]], "LINEAR")])
    path = tmp_path / "rig.glb"
    path.write_bytes(g.glb())
    return path, hips_at, turns


@pytest.mark.parametrize(
    "scale",
    [(0.01, 0.01, 0.01), (0.01, 0.02, 0.015), (-0.01, 0.01, 0.01)],
    ids=["uniform", "non-uniform", "mirrored"],
)
def test_a_foreign_rig_reads_with_its_parents_scale_rest_rotations_and_interpolation(scale, tmp_path):
    path, hips_at, turns = _rig(tmp_path, scale)
    motion = load(path, fps=4)
    assert motion.skeleton.names == ("hips", "spine", "head") and motion.num_frames == 5 and motion.fps == 4
    armature = _matrix(q=_axis_quat_xyzw((1, 0, 0), -90), s=scale)
    for frame in range(5):
        t = frame / 4
        k = min(int(t / 0.5), 1)
        u = (t - 0.5 * k) / 0.5
        hip = (1 - u) * np.array(hips_at[k]) + u * np.array(hips_at[k + 1])  # LINEAR
        turn = turns[min(int(t / 0.5 + 1e-9), 2)]  # STEP: a key holds until the next
        world = [armature @ _matrix(hip, turn)]
        world.append(world[-1] @ _matrix((0, 20, 0), _axis_quat_xyzw((0, 0, 1), 30)))
        world.append(world[-1] @ _matrix((0, 15, 0)))
        expected = np.array([m[:3, 3] for m in world])
        assert np.abs(motion.positions_m()[frame] - expected).max() < 1e-6, frame


def test_a_mirroring_node_matrix_keeps_the_joint_positions(tmp_path):
    g = GltfBuilder()
    mirror = np.diag([-2.0, 2.0, 2.0, 1.0])
    mirror[:3, 3] = [0, 1, 0]
    g.doc["nodes"] = [
        {"name": "mirror", "matrix": mirror.T.ravel().tolist(), "children": [1]},
        {"name": "hip", "children": [2]},
        {"name": "tip", "translation": [1, 0, 0]},
    ]
    g.animation(
        "turn", [(1, "rotation", [0, 1.0], [_axis_quat_xyzw((0, 0, 1), 0), _axis_quat_xyzw((0, 0, 1), 90)], "LINEAR")]
    )
    (tmp_path / "m.glb").write_bytes(g.glb())
    motion = load(tmp_path / "m.glb", fps=2)
    angle = np.radians([0, 45, 90])
    tip = np.stack([-2 * np.cos(angle), 1 + 2 * np.sin(angle), 0 * angle], axis=1)
    assert np.abs(motion.positions_m()[:, motion.skeleton.index("tip")] - tip).max() < 1e-9


def test_an_animation_is_chosen_by_name_or_index(tmp_path):
    path, _, _ = _rig(tmp_path)
    by_name, by_index = load(path, animation="wave"), load(path, animation=1)
    assert np.array_equal(by_name.channels, by_index.channels)
    assert (by_name.num_frames, load(path).num_frames) == (31, 31)  # sparse keys: 30 fps over 1 s
    with pytest.raises(FormatError, match="no animation named 'run' .*'walk', 'wave'"):
        load(path, animation="run")
    with pytest.raises(FormatError, match="animation index 2 out of range"):
        load(path, animation=2)


def test_cubic_spline_keys_follow_the_hermite_curve(tmp_path):
    g = GltfBuilder()
    g.doc["nodes"] = [{"name": "root", "children": [1]}, {"name": "tip", "translation": [0, 1, 0]}]
    # (in-tangent, value, out-tangent) per key; zero tangents make the smoothstep 3u^2 - 2u^3
    values = [[0, 0, 0], [0, 0, 0], [0, 0, 0], [0, 0, 0], [1, 0, 0], [0, 0, 0]]
    g.animation("slide", [(0, "translation", [0, 1.0], values, "CUBICSPLINE")])
    (tmp_path / "slide.glb").write_bytes(g.glb())
    motion = load(tmp_path / "slide.glb", fps=4)
    u = np.arange(5) / 4
    assert np.allclose(motion.positions_m()[:, 0, 0], 3 * u**2 - 2 * u**3, atol=1e-12)


# ----- hostile files -------------------------------------------------------------------------


def _damaged(tmp_path, edit) -> object:
    g = GltfBuilder()
    g.doc["nodes"] = [{"name": "a", "children": [1]}, {"name": "b", "translation": [0, 1, 0]}]
    g.animation("move", [(0, "translation", [0, 1.0], [[0, 0, 0], [1, 0, 0]], "LINEAR")])
    g.glb()
    edit(g)
    if g.doc["buffers"][0].get("uri"):  # a .gltf whose buffer is somewhere else
        path = tmp_path / "bad.gltf"
        path.write_text(json.dumps(g.doc))
    else:
        path = tmp_path / "bad.glb"
        path.write_bytes(g.glb())
    return path


def _set(path: str, value):
    def edit(g):
        keys = path.split(".")
        target = g.doc
        for key in keys[:-1]:
            target = target[int(key)] if isinstance(target, list) else target[key]
        target[int(keys[-1]) if isinstance(target, list) else keys[-1]] = value

    return edit


HOSTILE = {
    "accessor count past its view": (_set("accessors.1.count", 10**6), "overrun|out of range"),
    "a huge count": (_set("accessors.0.count", 2**40), "count"),
    "a bufferView out of range": (_set("accessors.0.bufferView", 99), "bufferView index 99 out of range"),
    "an external buffer": (_set("buffers.0.uri", "../../etc/passwd"), "external file"),
    "a cycle of children": (_set("nodes.1.children", [0]), "two parents|cycle"),
    "a child out of range": (_set("nodes.0.children", [5]), "child index 5 out of range"),
    "values for other keys": (_set("accessors.0.count", 1), "values of 3 for 1 keys"),
    "no animations": (_set("animations", []), "no animation"),
    "an unknown interpolation": (_set("animations.0.samplers.0.interpolation", "BEZIER"), "interpolation"),
    "a glTF 1 asset": (_set("asset", {"version": "1.0"}), "version"),
    "a field of the wrong type": (_set("nodes.0.children", "zz"), r"nodes\[0\]\.children: expected a list"),
    "an index of the wrong type": (_set("animations.0.channels.0.sampler", -1), "expected a non-negative integer"),
    "a zero rotation key": (_set("nodes.1.rotation", [0, 0, 0, 0]), "not a unit quaternion"),
    "a transform that overflows": (_set("nodes.0.scale", [1e300] * 3), "beyond"),
}


@pytest.mark.parametrize("case", HOSTILE)
def test_a_damaged_gltf_gets_a_one_line_error(case, tmp_path):
    edit, message = HOSTILE[case]
    path = _damaged(tmp_path, edit)
    with pytest.raises(FormatError, match=message) as caught:
        load(path)
    assert "\n" not in str(caught.value) and str(path) in str(caught.value)


@pytest.mark.parametrize(
    "cut, expected",
    [
        (0, "empty file"),
        (4, "4 bytes: too short"),
        (11, "11 bytes: too short"),
        (19, "19 bytes: too short"),
        (30, "bytes at byte 8, the file has 30"),
        (200, "bytes at byte 8, the file has 200"),
    ],
)
def test_a_truncated_glb_gets_a_one_line_error(cut, expected, tmp_path):
    """How the file falls short: its size, or where its header says more."""
    data = _damaged(tmp_path, lambda g: None).read_bytes()
    (tmp_path / "cut.glb").write_bytes(data[:cut])
    with pytest.raises(FormatError, match=expected) as caught:
        load(tmp_path / "cut.glb")
    assert "\n" not in str(caught.value) and "cut.glb" in str(caught.value)


@pytest.mark.slow
def test_random_damage_never_escapes_as_another_exception(tmp_path):
    data = bytearray(to_gltf_bytes(load(DATA / "07_03.bvh")[:8], binary=True))
    rng = random.Random(7)
    for _ in range(300):
        damaged = bytearray(data)
        for _ in range(rng.randint(1, 6)):
            damaged[rng.randrange(len(damaged))] = rng.randrange(256)
        (tmp_path / "d.glb").write_bytes(damaged)
        try:
            load(tmp_path / "d.glb")
        except MocodecError:
            pass  # a one-line error, or a file that still reads


# ----- FBX -------------------------------------------------------------------------------------


def test_fbx_animation_curves_give_the_known_pose():
    """nod.fbx (hand-written ASCII FBX): Hips at 90 cm, Spine 10 above turning 0 -> 90 degrees
    about Z over 1 s (linear keys), Head 10 above the Spine."""
    pytest.importorskip("ufbx")
    motion = load(FBX_DATA / "nod.fbx", fps=4)
    assert motion.skeleton.names == ("Hips", "Spine", "Head") and motion.num_frames == 5
    assert motion.skeleton.units_per_metre == 100.0  # FBX's default unit, the centimetre
    angle = np.radians(90 * np.arange(5) / 4)
    head = np.stack((-10 * np.sin(angle), 100 + 10 * np.cos(angle), 0 * angle), axis=1)
    assert np.abs(motion.positions()[:, 2] - head).max() < 1e-9


@pytest.mark.parametrize("name, message", [("no_bones.fbx", "no skeleton"), ("no_take.fbx", "no animation stack")])
def test_an_fbx_without_a_skeletal_animation_gets_a_one_line_error(name, message):
    pytest.importorskip("ufbx")
    with pytest.raises(FormatError, match=message):
        load(FBX_DATA / name)


def test_a_file_that_is_not_fbx_gets_a_one_line_error(tmp_path):
    pytest.importorskip("ufbx")
    (tmp_path / "x.fbx").write_bytes(b"Kaydara FBX Binary  \0\x1a\0" + b"\xff" * 40)
    with pytest.raises(FormatError, match="not a readable FBX file"):
        load(tmp_path / "x.fbx")


# ----- every shared clip, and the command line ---------------------------------------------------

SHARED_CLIPS = (
    sorted((SHARED / "cmu").glob("*/*.bvh"))
    + sorted((SHARED / "cmu").glob("*/*.amc"))
    + sorted((SHARED / "bandai").rglob("*.bvh"))
    if SHARED
    else []
)


@pytest.mark.shared_data
@pytest.mark.parametrize("path", SHARED_CLIPS, ids=lambda p: p.name)
def test_every_shared_clip_survives_bvh_gltf_bvh(path, tmp_path):
    motion = load(path)
    save(motion, tmp_path / "m.glb")
    save(load(tmp_path / "m.glb"), tmp_path / "m.bvh")
    assert _joint_error_cm(motion, load(tmp_path / "m.bvh")) < 1e-4


def _cli(*args):
    return subprocess.run([sys.executable, "-m", "mocodec", *map(str, args)], capture_output=True, text=True)


def test_the_command_line_converts_encodes_and_reports_gltf(tmp_path):
    assert _cli("convert", DATA / "07_03.bvh", tmp_path / "walk.glb").returncode == 0
    assert _cli("convert", tmp_path / "walk.glb", tmp_path / "back.bvh").returncode == 0
    assert _joint_error_cm(load(DATA / "07_03.bvh"), load(tmp_path / "back.bvh")) < 1e-4
    info = _cli("info", tmp_path / "walk.glb")
    assert info.returncode == 0 and "57 joints" in info.stdout
    done = _cli("encode", tmp_path / "walk.glb", "-o", tmp_path / "walk.moc", "--max-error-cm", "1")
    assert done.returncode == 0, done.stderr
    assert _cli("decode", tmp_path / "walk.moc", "-o", tmp_path / "decoded.gltf").returncode == 0
    assert _joint_error_cm(load(tmp_path / "walk.glb"), load(tmp_path / "decoded.gltf")) <= 1.0 + 1e-6


def test_the_command_line_reads_fbx_and_refuses_bad_files_in_one_line(tmp_path):
    pytest.importorskip("ufbx")
    done = _cli("encode", FBX_DATA / "nod.fbx", "-o", tmp_path / "nod.moc", "--max-error-cm", "0.5")
    assert done.returncode == 0, done.stderr
    (tmp_path / "bad.glb").write_bytes(b"glTF\x02\0\0\0\xff\xff\0\0")
    for bad in (tmp_path / "bad.glb", FBX_DATA / "no_bones.fbx"):
        failed = _cli("info", bad)
        assert failed.returncode != 0 and failed.stderr.count("\n") == 1 and "Traceback" not in failed.stderr


def test_a_crash_inside_the_fbx_loader_is_a_one_line_error(monkeypatch):
    pytest.importorskip("ufbx")
    import os
    import signal

    from mocodec.formats import fbx

    monkeypatch.setattr(fbx, "_read", lambda *args: os.kill(os.getpid(), signal.SIGSEGV))
    with pytest.raises(FormatError, match=r"the FBX loader \(ufbx\) crashed on it \(signal SIGSEGV\): a damaged file"):
        load(FBX_DATA / "nod.fbx")


def test_a_crash_while_ufbx_frees_a_scene_is_no_error(monkeypatch):
    """The binding (0.0.5) can crash freeing a scene; the child never frees one, so a file
    without bones gets its own message, not a crash's."""
    pytest.importorskip("ufbx")
    import os
    import signal

    from mocodec.formats import fbx

    class SceneThatCrashesWhenFreed:
        nodes: list = []
        anim_stacks: list = []
        settings = None

        def __del__(self):
            os.kill(os.getpid(), signal.SIGSEGV)

    monkeypatch.setattr(fbx, "_load", lambda path: SceneThatCrashesWhenFreed())
    with pytest.raises(FormatError, match="no skeleton: the file has no bone nodes"):
        load(FBX_DATA / "nod.fbx")


@pytest.mark.parametrize(
    "module, action",
    [
        ("pygltflib", f"mocodec.save(mocodec.load({str(DATA.parent / 'formats' / 'walk.glb')!r}), 'x.glb')"),
        ("ufbx", f"mocodec.load({str(FBX_DATA / 'nod.fbx')!r})"),
    ],
)
def test_without_the_formats_extra_the_error_names_it(module, action, tmp_path):
    """glTF is read without the extra (the reader parses the JSON itself) and written with it."""
    script = f"import sys; sys.modules[{module!r}] = None\nimport mocodec\ntry:\n    {action}\n"
    script += "except mocodec.MocodecError as e:\n    print(e)"
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, cwd=tmp_path)
    assert "pip install 'mocodec[formats]'" in done.stdout, done.stderr


def test_a_motion_without_frames_is_refused_in_one_line(walk_bvh, tmp_path):
    from mocodec.errors import ConversionError

    with pytest.raises(ConversionError, match="at least one frame"):
        save(walk_bvh[:0], tmp_path / "empty.glb")
    assert not (tmp_path / "empty.glb").exists()

"""Real exporters' files: every take of every FBX and glTF file in ../shared/data gives, at every
frame, the joint world positions an independent evaluation gives (ufbx's own scene evaluation
for FBX; the raw keys composed here for glTF), and so do the BVH, ASF/AMC and glTF files
``save`` writes of it, read back. Tolerance: 1e-4 cm, or eight float32 steps at the skeleton's
largest coordinate where that is more (the file's own precision, ``nodetree.precision_m``)."""

from __future__ import annotations

import base64
import re

import numpy as np
import pytest

from conftest import DATA, SHARED
from gltf_builder import trs_matrix
from mocodec import load, sandbox, save
from mocodec.errors import ConversionError

#: Files of real exporters in the repository (tests/formats/fbx/exporters/README.md): fast tier.
EXPORTERS = sorted((DATA.parent / "formats" / "fbx" / "exporters").glob("*.fbx"))
#: The shared files: the slow tier.
SHARED_FBX = sorted((SHARED / "fbx").glob("*.fbx")) if SHARED else []
GLTF_FILES = sorted([*(SHARED / "gltf").glob("*.glb"), *(SHARED / "gltf").glob("*.gltf")]) if SHARED else []
FBX_FILES = [
    *(pytest.param(path, id=path.name) for path in EXPORTERS),
    *(pytest.param(path, id=path.name, marks=pytest.mark.shared_data) for path in SHARED_FBX),
]


def _tolerance_cm(reference_m: np.ndarray) -> float:
    """1e-4 cm, or eight float32 steps at the largest coordinate (metres) where that is more."""
    extent = np.float32(np.abs(reference_m).max())
    return max(1e-4, 8 * float(np.spacing(extent)) * 100)


def _node_of(name: str, names: list[str]) -> int:
    """The node a joint name stands for: its own name, or a made-unique ``name_K`` / ``nodeK``."""
    if names.count(name) == 1:
        return names.index(name)
    m = re.fullmatch(r"(?:.*_|node)(\d+)", name)
    assert m, f"joint {name!r} names no node"
    return int(m.group(1))


def _written_back(motion, tmp_path):
    """(format, motion read back) for each format ``save`` can write ``motion`` to."""
    out = []
    for ext in (".bvh", ".glb", ".amc"):
        try:
            save(motion, tmp_path / f"back{ext}")
        except ConversionError:
            assert ext == ".amc"  # a skeleton ASF cannot hold (translations below the root)
            continue
        out.append((ext, load(tmp_path / f"back{ext}", fps=motion.fps if ext == ".amc" else None)))
    return out


def _check(motion, reference, tmp_path):
    """``motion`` and what each writer makes of it match ``reference`` (frames, joints, 3)."""
    unit = motion.skeleton.units_per_metre
    tolerance = _tolerance_cm(reference / unit)
    error = np.abs(motion.positions() - reference).max() / unit * 100
    assert error <= tolerance, f"load: {error:.2e} cm"
    assert motion.skeleton.metadata["dropped_m"] * 100 <= tolerance
    for ext, back in _written_back(motion, tmp_path):
        sk = back.skeleton
        if ext == ".amc":  # ASF names its root 'root', its leaves' ends '<bone>_end', adds links
            names = motion.skeleton.names
            parents = motion.skeleton.parents
            keep = [0] + [
                sk.index(n if n in sk.names else f"{names[parents[k]]}_end") for k, n in enumerate(names) if k
            ]
        else:  # every writer goes depth first, as the readers do
            assert len(sk) == len(motion.skeleton), ext
            keep = list(range(len(sk)))
        moved = back.positions()[:, keep] / sk.units_per_metre * unit
        assert back.num_frames == motion.num_frames and back.fps == pytest.approx(motion.fps), ext
        error = np.abs(moved - reference).max() / unit * 100
        assert error <= tolerance, f"{ext}: {error:.2e} cm"


# ----- FBX: ufbx's own evaluation of the scene --------------------------------------------------


def _ufbx_takes(path) -> int:
    return sandbox.call_isolated(_count_takes, path, what=str(path))


def _count_takes(path) -> int:
    import ufbx

    scene = ufbx.load_file(str(path), ignore_geometry=True)
    _HELD.append(scene)
    return len(list(scene.anim_stacks))


_HELD: list = []  # ufbx objects a child never frees (the binding may crash freeing them)


def _ufbx_positions(path, take: int, frames: int, fps: float, joints: list[str]) -> np.ndarray:
    """World positions of the nodes behind ``joints`` at ``frames`` times ``fps`` apart from the
    take's start, evaluated by ufbx."""
    import ufbx

    scene = ufbx.load_file(str(path), ignore_geometry=True, target_axes=ufbx.axes_right_handed_y_up)
    nodes = list(scene.nodes)
    stack = list(scene.anim_stacks)[take]
    _HELD.extend((scene, nodes, stack))
    times = float(stack.time_begin) + np.arange(frames) / fps
    names = [n.name for n in nodes]
    index = [_node_of(name, names) for name in joints]
    out = np.empty((len(times), len(joints), 3))
    for f, t in enumerate(times):
        evaluated = scene.evaluate(stack.anim, float(t))
        world = list(evaluated.nodes)
        out[f] = [tuple(world[k].node_to_world.c3) for k in index]
        del world  # before the scene they belong to
        del evaluated
    return out


@pytest.mark.parametrize("path", FBX_FILES)
def test_every_fbx_take_matches_ufbx_at_every_frame_and_after_every_writer(path, tmp_path):
    pytest.importorskip("ufbx")
    for take in range(_ufbx_takes(path)):
        motion = load(path, animation=take)
        names = list(motion.skeleton.names)
        reference = sandbox.call_isolated(
            _ufbx_positions, path, take, motion.num_frames, motion.fps, names, what=str(path), timeout_s=300.0
        )
        _check(motion, reference, tmp_path)


# ----- glTF: the raw keys, interpolated and composed here ---------------------------------------


def _slerp(a: np.ndarray, b: np.ndarray, u: float) -> np.ndarray:
    if np.dot(a, b) < 0:
        b = -b
    angle = np.arccos(np.clip(np.dot(a, b), -1.0, 1.0))
    if angle < 1e-9:
        return a
    return (np.sin((1 - u) * angle) * a + np.sin(u * angle) * b) / np.sin(angle)


def _gltf_positions(path, animation: int, times: np.ndarray, joints: list[str]) -> np.ndarray:
    """World positions (metres) of the nodes behind ``joints`` at ``times``: each node's key
    values interpolated linearly (slerp for rotations), node matrices composed from the root.
    A key within a thousandth of a frame of a time is that time's value (key times are 32-bit
    floats: a time on the frame grid is not the key's time to the last bit)."""
    import pygltflib

    g = pygltflib.GLTF2().load(str(path))
    blob = g.binary_blob() if str(path).endswith(".glb") else None

    def accessor(k):
        a = g.accessors[k]
        view = g.bufferViews[a.bufferView]
        data = blob if blob is not None else base64.b64decode(g.buffers[view.buffer].uri.partition(",")[2])
        width = {"SCALAR": 1, "VEC3": 3, "VEC4": 4}[a.type]
        start = (view.byteOffset or 0) + (a.byteOffset or 0)
        assert a.componentType == pygltflib.FLOAT and not view.byteStride
        return np.frombuffer(data, "<f4", a.count * width, start).reshape(a.count, width).astype(float)

    tracks = {}
    for channel in g.animations[animation].channels:
        sampler = g.animations[animation].samplers[channel.sampler]
        assert sampler.interpolation in (None, "LINEAR")
        tracks[(channel.target.node, channel.target.path)] = (accessor(sampler.input)[:, 0], accessor(sampler.output))

    def value(node, path, t, rest):
        if (node, path) not in tracks:
            return rest
        keys, values = tracks[(node, path)]
        nearest = int(np.abs(keys - t).argmin())
        if abs(keys[nearest] - t) < 1e-3 * (times[1] - times[0] if len(times) > 1 else 1.0):
            return values[nearest]
        if t <= keys[0] or len(keys) == 1:
            return values[0]
        if t >= keys[-1]:
            return values[-1]
        k = int(np.searchsorted(keys, t, side="right")) - 1
        u = (t - keys[k]) / (keys[k + 1] - keys[k])
        if path == "rotation":
            return _slerp(values[k], values[k + 1], u)
        return values[k] + u * (values[k + 1] - values[k])

    parents = {child: k for k, node in enumerate(g.nodes) for child in node.children or []}
    names = [n.name or "" for n in g.nodes]
    index = [_node_of(name, names) for name in joints]
    out = np.empty((len(times), len(joints), 3))
    for f, t in enumerate(times):
        world: dict[int, np.ndarray] = {}

        def world_of(k):
            if k not in world:
                node = g.nodes[k]
                if node.matrix is not None:
                    local = np.array(node.matrix, float).reshape(4, 4).T
                else:
                    xyzw = value(k, "rotation", t, node.rotation or [0, 0, 0, 1])
                    local = trs_matrix(
                        value(k, "translation", t, node.translation or [0, 0, 0]),
                        np.asarray(xyzw, float) / np.linalg.norm(xyzw),
                        value(k, "scale", t, node.scale or [1, 1, 1]),
                    )
                world[k] = world_of(parents[k]) @ local if k in parents else local
            return world[k]

        out[f] = [world_of(k)[:3, 3] for k in index]
    return out


@pytest.mark.shared_data
@pytest.mark.parametrize("path", GLTF_FILES, ids=lambda p: p.name)
def test_every_gltf_animation_matches_its_keys_at_every_frame_and_after_every_writer(path, tmp_path):
    pygltflib = pytest.importorskip("pygltflib")
    animations = len(pygltflib.GLTF2().load(str(path)).animations)
    for animation in range(animations):
        motion = load(path, animation=animation)
        first = min(float(t) for t in _key_starts(path, animation))
        times = first + np.arange(motion.num_frames) / motion.fps
        reference = _gltf_positions(path, animation, times, list(motion.skeleton.names))
        _check(motion, reference * motion.skeleton.units_per_metre, tmp_path)


def _key_starts(path, animation: int):
    import pygltflib

    g = pygltflib.GLTF2().load(str(path))
    for sampler in g.animations[animation].samplers:
        yield g.accessors[sampler.input].min[0]

"""Writing glTF 2.0 (``.gltf``, ``.glb``): one node per joint (its rest offset as the node's
translation, in metres as glTF requires), one skin over all joints (so loaders such as three.js
make them bones), and one animation sampling every frame: a rotation channel (quaternions) for
each joint that rotates, a translation channel for each joint that translates (a still pose:
the root's rotation), LINEAR between frames. With ``mesh="mannequin"`` the skin also has a body: the procedural
mannequin of :mod:`mocodec.mannequin` (positions, normals, four joints and weights a vertex, as
bytes), on a node of its own beside the skeleton, its inverse bind matrices at the mannequin's
bind pose, so the file plays as a character in any glTF viewer. Each node's ``extras.mocodec`` keeps the joint's
channel layout (channels, Euler order, ASF axis, exact offset) and the asset's
``extras.mocodec`` the unit and frame rate, so a file read back (:mod:`.gltf`) has the same
skeleton; other readers ignore them. Values are 32-bit floats, as glTF stores them. Needs
the ``formats`` extra (pygltflib)."""

from __future__ import annotations

import base64
import os
from pathlib import Path

import numpy as np

from mocodec import mannequin, rotations
from mocodec.errors import ConversionError
from mocodec.extras import require
from mocodec.formats import nodetree
from mocodec.formats.fileio import atomic_write_bytes
from mocodec.motion import Motion
from mocodec.skeleton import POSITION_CHANNELS
from mocodec.version import __version__

_FLOAT, _UBYTE, _USHORT, _UINT = 5126, 5121, 5123, 5125
_DTYPES = {_FLOAT: "<f4", _UBYTE: "u1", _USHORT: "<u2", _UINT: "<u4"}
_VERTICES, _INDICES = 34962, 34963  # buffer view targets
MESHES = ("mannequin",)  # what ``mesh`` may name


def _pygltflib():
    return require("pygltflib", "formats", "glTF export")


# ----- writing -------------------------------------------------------------------------------


class _Blob:
    """The binary buffer and its views and accessors, built up one array at a time."""

    def __init__(self, gltf):
        self.gltf = gltf
        self.data = bytearray()

    def add(
        self,
        values: np.ndarray,
        kind: str,
        with_bounds: bool = False,
        component: int = _FLOAT,
        normalized: bool = False,
        target: int | None = None,
    ) -> int:
        g = _pygltflib()
        array = np.ascontiguousarray(values, dtype=_DTYPES[component])
        self.data += b"\0" * (-len(self.data) % 4)
        view = g.BufferView(buffer=0, byteOffset=len(self.data), byteLength=array.nbytes, target=target)
        self.data += array.tobytes()
        self.gltf.bufferViews.append(view)
        count = array.shape[0]
        accessor = g.Accessor(
            bufferView=len(self.gltf.bufferViews) - 1, componentType=component, count=count, type=kind
        )
        if normalized:
            accessor.normalized = True
        if with_bounds:
            flat = array.reshape(count, -1)
            accessor.min = [float(v) for v in flat.min(axis=0)]
            accessor.max = [float(v) for v in flat.max(axis=0)]
        self.gltf.accessors.append(accessor)
        return len(self.gltf.accessors) - 1


def to_gltf_bytes(motion: Motion, binary: bool, animation_name: str = "", mesh: str | None = None) -> bytes:
    """``motion`` as a ``.glb`` (``binary``) or a self-contained ``.gltf`` (buffer as a data
    URI), with the body ``mesh`` names (one of MESHES) or none."""
    g = _pygltflib()
    if motion.num_frames == 0:
        raise ConversionError("a glTF animation needs at least one frame; the motion has none")
    if mesh is not None and mesh not in MESHES:
        raise ConversionError(f"unknown mesh {mesh!r} (expected one of: {', '.join(MESHES)})")
    sk = motion.skeleton
    translation, rotation = nodetree.from_motion(motion)
    gltf = g.GLTF2(asset=g.Asset(version="2.0", generator=f"mocodec {__version__}"))
    gltf.asset.extras = {"mocodec": {"units_per_metre": sk.units_per_metre, "fps": motion.fps}}
    blob = _Blob(gltf)
    for i, joint in enumerate(sk.joints):
        node = g.Node(name=joint.name, children=list(sk.children[i]) or [])
        node.translation = [float(v) for v in sk.offsets[i] / sk.units_per_metre]
        node.extras = {"mocodec": nodetree.layout_of(joint)}
        gltf.nodes.append(node)
    gltf.scenes = [g.Scene(nodes=[0])]
    gltf.scene = 0
    bind = mannequin.bind_positions(sk, motion.channels[0]) if mesh else sk.rest_positions
    rest = bind / sk.units_per_metre
    inverse_bind = np.tile(np.eye(4), (len(sk), 1, 1))
    inverse_bind[:, :3, 3] = -rest
    # glTF matrices are column-major: the transpose's rows are the columns
    gltf.skins = [
        g.Skin(
            joints=list(range(len(sk))),
            skeleton=0,
            inverseBindMatrices=blob.add(inverse_bind.transpose(0, 2, 1).reshape(len(sk), 16), "MAT4"),
        )
    ]
    times = blob.add(np.arange(motion.num_frames) / motion.fps, "SCALAR", with_bounds=True)
    animation = g.Animation(name=animation_name or sk.name or "motion")
    for i, joint in enumerate(sk.joints):
        paths = []
        if any(c in POSITION_CHANNELS for c in joint.channels):
            paths.append(("translation", translation[:, i], "VEC3"))
        if joint.rotation_order:
            xyzw = rotations.quat_continuous(rotation[:, i])[:, [1, 2, 3, 0]]
            paths.append(("rotation", xyzw, "VEC4"))
        for path, values, kind in paths:
            animation.samplers.append(g.AnimationSampler(input=times, output=blob.add(values, kind)))
            target = g.AnimationChannelTarget(node=i, path=path)
            animation.channels.append(g.AnimationChannel(sampler=len(animation.samplers) - 1, target=target))
    if not animation.channels:  # a still pose: the root's rotation keeps its frames
        xyzw = np.tile(rotation[0, 0, [1, 2, 3, 0]], (motion.num_frames, 1))
        animation.samplers.append(g.AnimationSampler(input=times, output=blob.add(xyzw, "VEC4")))
        target = g.AnimationChannelTarget(node=0, path="rotation")
        animation.channels.append(g.AnimationChannel(sampler=0, target=target))
    gltf.animations = [animation]
    if mesh:
        _add_mannequin(gltf, blob, mannequin.build(sk, bind), sk.units_per_metre)
    data = bytes(blob.data) + b"\0" * (-len(blob.data) % 4)
    if binary:
        gltf.buffers = [g.Buffer(byteLength=len(data))]
        gltf.set_binary_blob(data)
        return b"".join(gltf.save_to_bytes())
    uri = "data:application/octet-stream;base64," + base64.b64encode(data).decode("ascii")
    gltf.buffers = [g.Buffer(byteLength=len(data), uri=uri)]
    return gltf.gltf_to_json().encode("utf-8")


def _add_mannequin(gltf, blob: _Blob, body: mannequin.Mesh, units_per_metre: float) -> None:
    """The mannequin as the skin's mesh, on a root node of its own (glTF ignores a skinned
    node's transform): positions in metres, joints and weights as bytes (weights summing to
    255 of 255) where the skeleton has fewer than 256 joints."""
    g = _pygltflib()
    joints = _UBYTE if body.joints.max() < 256 else _USHORT
    weights = np.round(body.weights * 255.0).astype(np.int64)
    top = weights.argmax(axis=1)
    weights[np.arange(len(weights)), top] += 255 - weights.sum(axis=1)  # the rounding goes to the largest
    count = len(body.positions)
    attributes = g.Attributes(
        POSITION=blob.add(body.positions / units_per_metre, "VEC3", with_bounds=True, target=_VERTICES),
        NORMAL=blob.add(body.normals, "VEC3", target=_VERTICES),
        JOINTS_0=blob.add(body.joints, "VEC4", component=joints, target=_VERTICES),
        WEIGHTS_0=blob.add(weights, "VEC4", component=_UBYTE, normalized=True, target=_VERTICES),
    )
    indices = blob.add(
        body.triangles.reshape(-1), "SCALAR", component=_USHORT if count < 65536 else _UINT, target=_INDICES
    )
    # a matte grey: glTF's default material is fully metallic, which renders black without an environment
    gltf.materials = [
        g.Material(
            name="mannequin",
            pbrMetallicRoughness=g.PbrMetallicRoughness(
                baseColorFactor=[0.62, 0.66, 0.74, 1.0], metallicFactor=0.0, roughnessFactor=0.8
            ),
        )
    ]
    primitive = g.Primitive(attributes=attributes, indices=indices, material=0)
    gltf.meshes = [g.Mesh(name="mannequin", primitives=[primitive])]
    gltf.nodes.append(g.Node(name="mannequin", mesh=0, skin=0))
    gltf.scenes[0].nodes.append(len(gltf.nodes) - 1)


def write_gltf(motion: Motion, path: str | os.PathLike, animation_name: str = "", mesh: str | None = None) -> None:
    """Write ``motion`` as ``.glb`` or ``.gltf`` (by extension), atomically, with the body
    ``mesh`` names (``"mannequin"``) or none."""
    binary = Path(path).suffix.lower() == ".glb"
    atomic_write_bytes(path, to_gltf_bytes(motion, binary, animation_name, mesh))

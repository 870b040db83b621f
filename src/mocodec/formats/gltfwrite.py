"""Writing glTF 2.0 (``.gltf``, ``.glb``): one node per joint (its rest offset as the node's
translation, in metres as glTF requires), one skin over all joints (so loaders such as three.js
make them bones), and one animation sampling every frame: a rotation channel (quaternions) for
each joint that rotates, a translation channel for each joint that translates (a still pose:
the root's rotation), LINEAR between frames. Each node's ``extras.mocodec`` keeps the joint's
channel layout (channels, Euler order, ASF axis, exact offset) and the asset's
``extras.mocodec`` the unit and frame rate, so a file read back (:mod:`.gltf`) has the same
skeleton; other readers ignore them. Values are 32-bit floats, as glTF stores them. Needs
the ``formats`` extra (pygltflib)."""

from __future__ import annotations

import base64
import os
from pathlib import Path

import numpy as np

from mocodec import rotations
from mocodec.errors import ConversionError
from mocodec.extras import require
from mocodec.formats import nodetree
from mocodec.formats.fileio import atomic_write_bytes
from mocodec.motion import Motion
from mocodec.skeleton import POSITION_CHANNELS
from mocodec.version import __version__

_FLOAT = 5126


def _pygltflib():
    return require("pygltflib", "formats", "glTF export")


# ----- writing -------------------------------------------------------------------------------


class _Blob:
    """The binary buffer and its views and accessors, built up one array at a time."""

    def __init__(self, gltf):
        self.gltf = gltf
        self.data = bytearray()

    def add(self, values: np.ndarray, kind: str, with_bounds: bool = False) -> int:
        g = _pygltflib()
        array = np.ascontiguousarray(values, dtype="<f4")
        self.data += b"\0" * (-len(self.data) % 4)
        view = g.BufferView(buffer=0, byteOffset=len(self.data), byteLength=array.nbytes)
        self.data += array.tobytes()
        self.gltf.bufferViews.append(view)
        count = array.shape[0]
        accessor = g.Accessor(bufferView=len(self.gltf.bufferViews) - 1, componentType=_FLOAT, count=count, type=kind)
        if with_bounds:
            flat = array.reshape(count, -1)
            accessor.min = [float(v) for v in flat.min(axis=0)]
            accessor.max = [float(v) for v in flat.max(axis=0)]
        self.gltf.accessors.append(accessor)
        return len(self.gltf.accessors) - 1


def to_gltf_bytes(motion: Motion, binary: bool, animation_name: str = "") -> bytes:
    """``motion`` as a ``.glb`` (``binary``) or a self-contained ``.gltf`` (buffer as a data URI)."""
    g = _pygltflib()
    if motion.num_frames == 0:
        raise ConversionError("a glTF animation needs at least one frame; the motion has none")
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
    rest = sk.rest_positions / sk.units_per_metre
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
    data = bytes(blob.data) + b"\0" * (-len(blob.data) % 4)
    if binary:
        gltf.buffers = [g.Buffer(byteLength=len(data))]
        gltf.set_binary_blob(data)
        return b"".join(gltf.save_to_bytes())
    uri = "data:application/octet-stream;base64," + base64.b64encode(data).decode("ascii")
    gltf.buffers = [g.Buffer(byteLength=len(data), uri=uri)]
    return gltf.gltf_to_json().encode("utf-8")


def write_gltf(motion: Motion, path: str | os.PathLike, animation_name: str = "") -> None:
    """Write ``motion`` as ``.glb`` or ``.gltf`` (by extension), atomically."""
    binary = Path(path).suffix.lower() == ".glb"
    atomic_write_bytes(path, to_gltf_bytes(motion, binary, animation_name))

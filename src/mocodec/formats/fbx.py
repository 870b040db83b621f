"""FBX animations (``.fbx``, binary or ASCII) through the ufbx loader (the ``ufbx`` package).

The skeleton is the file's bone nodes with every node between them and their common ancestor.
An animation stack (``animation``: a name or an index, the first by default) is sampled over
its time span at ``fps`` (by default the file's frame rate) by ufbx's own evaluation of the
whole scene, so pre- and post-rotations, pivots, layers, scale inheritance and the transforms
above the skeleton are all in the world transforms the joints are made from
(:mod:`mocodec.formats.nodetree`). Axes are converted to glTF's and BVH's convention
(right-handed, Y up); lengths keep the file's unit (FBX's default, centimetres, is 100 units
per metre). A take whose curves hold still gives a motion that holds still.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from mocodec import limits, rotations, sandbox
from mocodec.errors import ConversionError, CorruptStreamError, FormatError
from mocodec.extras import require
from mocodec.formats import nodetree
from mocodec.motion import Motion

#: The ufbx objects a loader's child never frees: the binding (0.0.5) can crash while it frees
#: a scene, and the child exits without freeing anything.
_HELD: list = []

#: How long the loader's child may take: ufbx evaluates the whole scene at each frame, so the
#: longest take the frame limit lets through needs tens of seconds (docs/formats.md).
READ_TIMEOUT_S = 300.0
#: Frames sampled together (their matrices, then the rotations in them).
SAMPLE_BLOCK = 4096


def _ufbx():
    return require("ufbx", "formats", "FBX import")


def _load(path: Path):
    ufbx = _ufbx()
    if not path.is_file():
        raise FormatError(path, None, "no such file" if not path.exists() else "is not a file")
    try:
        return ufbx.load_file(
            str(path),
            ignore_geometry=True,
            ignore_embedded=True,
            load_external_files=False,
            target_axes=ufbx.axes_right_handed_y_up,
        )
    except ufbx.UfbxError as e:
        raise FormatError(path, None, f"not a readable FBX file: {e}"[:300]) from None


def _choose_stack(path: Path, stacks: list, animation: str | int | None):
    if not stacks:
        raise FormatError(path, None, "no animation stack (take): the file holds no motion")
    if animation is None:
        return stacks[0]
    if isinstance(animation, int) or str(animation).isdigit():
        k = int(animation)
        if not 0 <= k < len(stacks):
            raise FormatError(path, None, f"animation index {k} out of range (the file has {len(stacks)})")
        return stacks[k]
    for stack in stacks:
        if stack.name == animation:
            return stack
    names = ", ".join(repr(s.name) for s in stacks)
    raise FormatError(path, None, f"no animation named {animation!r} (the file has {names})")


def read_fbx(path: str | os.PathLike, *, animation: str | int | None = None, fps: float | None = None) -> Motion:
    """The skeletal motion of one animation stack of an FBX file (see the module docstring).

    ufbx is native code reading a file nobody has checked, through young bindings: it runs in
    a child process (:mod:`mocodec.sandbox`), so a crash, a runaway allocation or a hang is a
    one-line error here, not the end of the caller."""
    path = Path(path)
    _ufbx()  # a missing extra is named here, not in the child
    try:
        kind, value = sandbox.call_isolated(
            _read_outcome, path, animation, fps, what=str(path), timeout_s=READ_TIMEOUT_S
        )
    except sandbox.NativeCrash as e:
        raise FormatError(
            path, None, f"the FBX loader (ufbx) crashed on it ({e.how}): a damaged file, or one its binding cannot read"
        ) from None
    except CorruptStreamError as e:
        raise FormatError(path, None, f"the FBX loader failed on it: {str(e).removeprefix(f'{path}: ')}") from None
    if kind == "error":
        raise FormatError(path, None, value)
    return value


def _read_outcome(path: Path, animation: str | int | None, fps: float | None) -> tuple[str, object]:
    """("motion", the motion) or ("error", the FormatError's message): what the child sends."""
    try:
        return "motion", _read(path, animation, fps)
    except FormatError as e:
        return "error", e.message


def _read(path: Path, animation: str | int | None, fps: float | None) -> Motion:
    scene = _load(path)
    # each of ufbx's lists is copied into a Python list once: walking one of them a second
    # time crashes the binding (0.0.5)
    nodes = list(scene.nodes)
    stacks = list(scene.anim_stacks)
    settings = scene.settings
    _HELD.extend((scene, nodes, stacks, settings))
    parents = np.array([n.parent.typed_id if n.parent is not None else -1 for n in nodes], dtype=np.int64)
    if any(n.typed_id != k for k, n in enumerate(nodes)) or (parents >= np.arange(len(nodes))).any():
        raise FormatError(path, None, "the node list is not in parents-first order")
    problem = nodetree.tree_problem(parents)
    if problem:
        raise FormatError(path, None, problem)
    bones = {k for k, n in enumerate(nodes) if n.bone is not None}
    if not bones:
        raise FormatError(path, None, "no skeleton: the file has no bone nodes")
    stack = _choose_stack(path, stacks, animation)
    keep = nodetree.closure(parents, bones)
    if keep is None:  # pragma: no cover - every FBX node hangs below the scene's root node
        raise FormatError(path, None, "the bones have no common ancestor node")
    rate = float(fps or settings.frames_per_second)
    if not limits.fps_ok(rate):
        raise FormatError(path, None, f"frame rate {rate} out of range {limits.FPS_RANGE}; give fps")
    begin, end = float(stack.time_begin), float(stack.time_end)
    frames = int(round((end - begin) * rate)) + 1 if np.isfinite(end - begin) else 0
    if not 0 < frames <= limits.MAX_DECODED_VALUES // (7 * len(keep)):
        raise FormatError(path, None, f"take {stack.name!r} spans {frames} frames: out of range")
    if frames * len(nodes) > limits.MAX_NODE_FRAMES:
        raise FormatError(
            path,
            None,
            f"take {stack.name!r}: {frames} frames of {len(nodes)} nodes, past {limits.MAX_NODE_FRAMES} to evaluate; "
            "give a lower fps",
        )
    position, rotation = _world(scene, stack.anim, keep, begin + np.arange(frames) / rate)
    unit = float(settings.unit_meters)
    units_per_metre = 1.0 / unit if np.isfinite(unit) and unit > 0 else 100.0
    names = nodetree.unique_names([nodes[k].name for k in keep], keep)
    joints = nodetree.NodeSamples(names, nodetree.joint_parents(parents, keep), position / units_per_metre, rotation)
    try:
        return nodetree.to_motion(joints, rate, units_per_metre, stack.name or path.stem)
    except ConversionError as e:
        raise FormatError(path, None, str(e)) from None


def _world(scene, anim, keep: list[int], times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """World positions (file units) and rotations ``(w, x, y, z)`` of the nodes ``keep`` at
    ``times``, from the scene ufbx evaluates at each time; SAMPLE_BLOCK frames of matrices at
    a time, so memory is that of the result."""
    position = np.empty((len(times), len(keep), 3))
    rotation = np.empty((len(times), len(keep), 4))
    for first in range(0, len(times), SAMPLE_BLOCK):
        block = times[first : first + SAMPLE_BLOCK]
        matrices = np.empty((len(block), len(keep), 3, 4))
        for f, t in enumerate(block):
            evaluated = scene.evaluate(anim, float(t))
            evaluated_nodes = list(evaluated.nodes)
            for k, node in enumerate(keep):
                matrices[f, k] = np.array(evaluated_nodes[node].node_to_world).T
            del evaluated_nodes  # before the scene they belong to
            del evaluated
        u, _, vt = np.linalg.svd(matrices[..., :3])
        position[first : first + len(block)] = matrices[..., 3]
        rotation[first : first + len(block)] = rotations.matrix_to_quat(u @ vt)
    return position, rotation

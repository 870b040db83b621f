"""Reading glTF 2.0 (``.gltf``, ``.glb``) animations: a skeleton as a node hierarchy, sampled
motion (writing: :mod:`.gltfwrite`; what the document must look like: :mod:`.gltfschema`).

The skeleton is the first skin's joints (or, without a skin, the nodes the animation
moves and the nodes between them), with the transforms above them composed into the root;
the animation (``animation``: a name or an index, the first by default) is sampled at ``fps``
from its first key to its last, with STEP, LINEAR (slerp) and CUBICSPLINE interpolation. By
default the rate is the grid the key times sit on (a baked animation's), else 30 fps (adjusted
so the last key falls on a frame; :func:`_frame_rate`). Buffers must be inside the file (a
``.glb`` chunk or a ``data:`` URI): a buffer naming another file is refused, as mocodec never
opens a path a file names.
"""

from __future__ import annotations

import base64
import binascii
import json
import os
import struct
from pathlib import Path
from typing import Any

import numpy as np

from mocodec import limits, rotations
from mocodec.errors import ConversionError, FormatError
from mocodec.formats import nodetree
from mocodec.formats.fileio import read_bytes
from mocodec.formats.gltfschema import SCHEMA, Fields, schema_error, small_int
from mocodec.motion import Motion

_GLB_MAGIC = b"glTF"
_CHUNK_JSON = 0x4E4F534A
_CHUNK_BIN = 0x004E4942
_FLOAT = 5126
_COMPONENTS = {5120: np.int8, 5121: np.uint8, 5122: np.int16, 5123: np.uint16, 5125: np.uint32, _FLOAT: np.float32}
_NORMALISE = {5120: 127.0, 5121: 255.0, 5122: 32767.0, 5123: 65535.0}
_WIDTHS = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT4": 16}
#: Bytes a glTF file may have: its buffers are read into memory whole.
MAX_FILE_BYTES = 1 << 31
#: Values all accessors together may convert, per byte of the file (float64: 8 bytes each).
ACCESSOR_VALUES_PER_BYTE = 2
#: Frame rate of a clip whose keys do not sit on a grid of at least MIN_GRID_FPS (a few
#: authored keys, or keys at irregular times): adjusted so the last key falls on a frame.
FALLBACK_FPS = 30.0
#: The lowest key rate taken for a sampling grid: sparser keys are an animator's keyframes,
#: played back interpolated, not samples.
MIN_GRID_FPS = 10.0
#: How far (in frames) a key time may be from the grid and still sit on it (key times are
#: 32-bit floats).
_GRID_SLACK_FRAMES = 1e-2


class Document:
    """A parsed glTF document with checked access to its arrays. Each accessor is converted
    once, and all of them together to at most ACCESSOR_VALUES_PER_BYTE values per byte of the
    file: memory in proportion to the file, however many channels share an accessor or how
    many values an accessor without data declares."""

    def __init__(self, path: Path, gltf: Any, binary_chunk: bytes | None, file_bytes: int):
        self.path = path
        self.gltf = gltf
        self.binary_chunk = binary_chunk
        self._buffers: dict[int, bytes] = {}
        self._arrays: dict[int, np.ndarray] = {}
        self.values_left = ACCESSOR_VALUES_PER_BYTE * file_bytes + 4096

    def fail(self, message: str) -> FormatError:
        return FormatError(self.path, None, message)

    def item(self, items, index, what: str):
        if not isinstance(index, int) or isinstance(index, bool) or not 0 <= index < len(items or []):
            raise self.fail(f"{what} index {index!r} out of range (the file has {len(items or [])})")
        return items[index]

    def buffer(self, index: int) -> bytes:
        if index not in self._buffers:
            buffer = self.item(self.gltf.buffers, index, "buffer")
            uri = buffer.uri
            if uri is None:
                if index != 0 or self.binary_chunk is None:
                    raise self.fail(f"buffer {index} has no data (no uri and no .glb binary chunk)")
                data = self.binary_chunk
            elif isinstance(uri, str) and uri.startswith("data:"):
                head, _, body = uri.partition(",")
                if not head.endswith(";base64"):
                    raise self.fail(f"buffer {index}: data URI is not base64")
                try:
                    data = base64.b64decode(body, validate=True)
                except (binascii.Error, ValueError):
                    raise self.fail(f"buffer {index}: data URI is not valid base64") from None
            else:
                raise self.fail(
                    f"buffer {index} names an external file ({str(uri)[:60]!r}); mocodec reads buffers "
                    "only inside the file (.glb, or .gltf with data: URIs)"
                )
            length = buffer.byteLength
            if not isinstance(length, int) or length < 0 or length > len(data):
                raise self.fail(f"buffer {index}: byteLength {length!r} but {len(data)} bytes of data")
            self._buffers[index] = data
        return self._buffers[index]

    def array(self, index: int, what: str) -> np.ndarray:
        """Accessor ``index`` as float64 ``(count, width)``, every offset checked first."""
        if index not in self._arrays:
            self._arrays[index] = self.convert(index, what)
        return self._arrays[index]

    def _charge(self, values: int, where: str) -> None:
        if values > self.values_left:
            raise self.fail(f"{where}: {values} values, more than the file's size allows ({self.values_left} left)")
        self.values_left -= values

    def convert(self, index: int, what: str) -> np.ndarray:
        accessor = self.item(self.gltf.accessors, index, f"{what} accessor")
        where = f"accessor {index} ({what})"
        if getattr(accessor, "sparse", None) is not None:
            raise self.fail(f"{where} is sparse, which mocodec does not read")
        dtype = _COMPONENTS.get(accessor.componentType)
        width = _WIDTHS.get(accessor.type)
        count = accessor.count
        if dtype is None or width is None:
            raise self.fail(f"{where}: unknown componentType {accessor.componentType!r} or type {accessor.type!r}")
        if not isinstance(count, int) or not 0 < count <= limits.MAX_DECODED_VALUES // width:
            raise self.fail(f"{where}: count {count!r} out of range")
        if accessor.bufferView is None:
            self._charge(count * width, where)
            return np.zeros((count, width))
        view = self.item(self.gltf.bufferViews, accessor.bufferView, f"{where} bufferView")
        data = self.buffer(view.buffer)
        item = np.dtype(dtype).itemsize
        element = item * width
        stride = view.byteStride or element
        start = (view.byteOffset or 0) + (accessor.byteOffset or 0)
        view_end = (view.byteOffset or 0) + (view.byteLength or 0)
        if not all(isinstance(v, int) and v >= 0 for v in (start, stride, view_end)):
            raise self.fail(f"{where}: bad offsets")
        end = start + stride * (count - 1) + element
        if stride < element or end > view_end or view_end > len(data) or start % item:
            raise self.fail(f"{where}: {count} elements from byte {start} overrun its view or buffer")
        self._charge(count * width, where)
        raw = np.ndarray(
            (count, width), dtype=np.dtype(dtype).newbyteorder("<"), buffer=data, offset=start, strides=(stride, item)
        )
        with np.errstate(all="ignore"):  # NaN and infinity are refused just below
            values = raw.astype(np.float64)
        if accessor.componentType in _NORMALISE and accessor.normalized:
            values = np.maximum(values / _NORMALISE[accessor.componentType], -1.0)
        if not np.isfinite(values).all():
            raise self.fail(f"{where}: not finite")
        return values


def _split_glb(path: Path, data: bytes) -> tuple[str, bytes | None]:
    """The JSON text and binary chunk of a ``.glb`` (header and chunk lengths checked)."""
    if len(data) < 20:
        raise FormatError(path, None, f"{len(data)} bytes: too short for a .glb (12-byte header and a chunk)")
    magic, version, length = struct.unpack_from("<4sII", data)
    if magic != _GLB_MAGIC:
        raise FormatError(path, None, f"not a .glb file: magic {magic!r} at byte 0, expected b'glTF'")
    if version != 2:
        raise FormatError(path, None, f"glTF binary version {version} at byte 4, expected 2")
    if length > len(data):
        raise FormatError(path, None, f"header says {length} bytes at byte 8, the file has {len(data)}")
    chunks: list[tuple[int, bytes]] = []
    offset = 12
    while offset + 8 <= length:
        size, kind = struct.unpack_from("<II", data, offset)
        if offset + 8 + size > length:
            raise FormatError(path, None, f"chunk at byte {offset} claims {size} bytes past the file's end")
        chunks.append((kind, data[offset + 8 : offset + 8 + size]))
        offset += 8 + size
    if not chunks or chunks[0][0] != _CHUNK_JSON:
        raise FormatError(path, None, "the first chunk (byte 12) is not JSON")
    binary = chunks[1][1] if len(chunks) > 1 and chunks[1][0] == _CHUNK_BIN else None
    try:
        return chunks[0][1].decode("utf-8"), binary
    except UnicodeDecodeError as e:
        raise FormatError(path, None, f"JSON chunk is not UTF-8 (byte {20 + e.start})") from None


def _parse(path: Path) -> Document:
    """The document, its JSON checked against SCHEMA and its node count against MAX_JOINTS
    before anything walks it (linear in the file: JSON objects become :class:`Fields`)."""
    data = read_bytes(path, MAX_FILE_BYTES)
    if not data:
        raise FormatError(path, None, "empty file (0 bytes): not a glTF file")
    if data[:4] == _GLB_MAGIC:
        text, binary = _split_glb(path, data)
    else:
        binary = None
        try:
            text = data.decode("utf-8")
        except UnicodeDecodeError as e:
            raise FormatError(path, None, f"not a .glb and not UTF-8 JSON (byte {e.start})") from None
    try:
        document = json.loads(text, object_hook=Fields, parse_int=small_int)
    except json.JSONDecodeError as e:
        raise FormatError(path, e.lineno, f"not JSON: {e.msg} (column {e.colno})") from None
    except RecursionError:
        raise FormatError(path, None, "JSON nested too deep") from None
    except ValueError as e:  # from small_int
        raise FormatError(path, None, str(e)) from None
    if not isinstance(document, dict) or not isinstance(document.get("asset"), dict):
        raise FormatError(path, None, "not a glTF document (no asset object)")
    nodes = document.get("nodes")
    if isinstance(nodes, list) and len(nodes) > limits.MAX_JOINTS:
        raise FormatError(path, None, f"{len(nodes)} nodes, more than a skeleton may have ({limits.MAX_JOINTS})")
    problem = schema_error(document, SCHEMA, "")
    if problem:
        raise FormatError(path, None, problem)
    version = str(document["asset"].get("version", ""))
    if not version.startswith("2."):
        raise FormatError(path, None, f"glTF version {version!r}, expected 2.x")
    return Document(path, document, binary, len(data))


def _vector(doc: Document, values, size: int, default: tuple, what: str) -> np.ndarray:
    if values is None:
        return np.array(default, dtype=np.float64)
    try:
        array = np.array(values, dtype=np.float64)
    except (TypeError, ValueError):
        array = np.zeros(0)
    if array.shape != (size,) or not np.isfinite(array).all():
        raise doc.fail(f"{what}: expected {size} finite numbers, got {str(values)[:60]}")
    return array


def _rest(doc: Document, k: int, node) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A node's own translation, rotation ``(w, x, y, z)`` and scale (from ``matrix`` if given)."""
    if node.matrix is not None:
        m = _vector(doc, node.matrix, 16, (), f"node {k} matrix").reshape(4, 4).T  # column-major
        scale = np.linalg.norm(m[:3, :3], axis=0)
        scale[0] *= np.sign(np.linalg.det(m[:3, :3]))  # a mirror: a negative scale on x
        if (np.abs(scale) < 1e-12).any() or abs(np.linalg.det(m[:3, :3] / scale) - 1.0) > 1e-4:
            raise doc.fail(f"node {k} matrix is not a rotation with a scale")
        return m[:3, 3], rotations.matrix_to_quat(m[:3, :3] / scale), scale
    translation = _vector(doc, node.translation, 3, (0.0, 0.0, 0.0), f"node {k} translation")
    xyzw = _vector(doc, node.rotation, 4, (0.0, 0.0, 0.0, 1.0), f"node {k} rotation")
    if not np.linalg.norm(xyzw) > 1e-12:
        raise doc.fail(f"node {k} rotation is not a unit quaternion")
    scale = _vector(doc, node.scale, 3, (1.0, 1.0, 1.0), f"node {k} scale")
    return translation, rotations.quat_normalize(xyzw[[3, 0, 1, 2]]), scale


def _tree(doc: Document) -> np.ndarray:
    """Each node's parent (-1 for none); FormatError for a node with two parents, a cycle or a
    tree deeper than MAX_DEPTH."""
    nodes = doc.gltf.nodes or []
    parents = -np.ones(len(nodes), dtype=np.int64)
    for k, node in enumerate(nodes):
        for child in node.children or []:
            doc.item(nodes, child, f"node {k} child")
            if parents[child] >= 0 or child == k:
                raise doc.fail(f"node {child} has two parents or is its own child (node {k})")
            parents[child] = k
    problem = nodetree.tree_problem(parents)
    if problem:
        raise doc.fail(problem)
    return parents


def _choose_animation(doc: Document, animation: str | int | None):
    animations = doc.gltf.animations or []
    if not animations:
        raise doc.fail("no animation: the file holds no motion to read")
    if animation is None:
        return animations[0]
    if isinstance(animation, int) or str(animation).isdigit():
        return doc.item(animations, int(animation), "animation")
    for a in animations:
        if a.name == animation:
            return a
    names = ", ".join(repr(a.name) for a in animations)
    raise doc.fail(f"no animation named {animation!r} (the file has {names})")


class _Track:
    """One animation channel: key times, values and how to interpolate between them."""

    def __init__(self, doc: Document, animation, channel, k: int):
        sampler = doc.item(animation.samplers, channel.sampler, f"channel {k} sampler")
        self.times = doc.array(sampler.input, "key times")[:, 0]
        if (np.diff(self.times) < 0).any():
            raise doc.fail(f"channel {k}: key times decrease")
        self.mode = sampler.interpolation or "LINEAR"
        if self.mode not in ("LINEAR", "STEP", "CUBICSPLINE"):
            raise doc.fail(f"channel {k}: unknown interpolation {self.mode!r}")
        self.path = channel.target.path
        values = doc.array(sampler.output, "key values")
        width = 4 if self.path == "rotation" else 3
        per_key = 3 if self.mode == "CUBICSPLINE" else 1
        if values.shape != (per_key * len(self.times), width):
            raise doc.fail(f"channel {k}: {values.shape[0]} values of {values.shape[1]} for {len(self.times)} keys")
        if self.path == "rotation":
            values = values[:, [3, 0, 1, 2]]  # (w, x, y, z)
            if per_key == 1 and not (np.linalg.norm(values, axis=1) > 1e-6).all():
                raise doc.fail(f"channel {k}: a rotation key is not a unit quaternion")
        self.values = values.reshape(len(self.times), per_key, width)

    def sample(self, start: float, rate: float, frames: int) -> np.ndarray:
        """Values at ``frames`` times from ``start`` at ``rate``. Keys on that grid (to within
        a thousandth of a frame: key times are 32-bit floats) give their values exactly."""
        times, n = self.times, len(self.times)
        key = self.values[:, 1] if self.mode == "CUBICSPLINE" else self.values[:, 0]
        if n == 1:
            return np.repeat(key[:1], frames, axis=0)
        t = start + np.arange(frames) / rate
        grid = (times - start) * rate
        if np.abs(grid - np.rint(grid)).max() < 1e-3:
            frame_of_key = np.rint(grid)
            nearest = np.searchsorted(frame_of_key, np.arange(frames)).clip(0, n - 1)
            t = np.where(frame_of_key[nearest] == np.arange(frames), times[nearest], t)
        k = np.clip(np.searchsorted(times, t, side="right") - 1, 0, n - 2)
        span = times[k + 1] - times[k]
        u = np.clip((t - times[k]) / np.where(span > 0, span, 1.0), 0.0, 1.0)
        if self.mode == "STEP":
            out = np.where((u >= 1.0)[:, None], key[k + 1], key[k])
        elif self.mode == "LINEAR":
            if self.path == "rotation":
                out = rotations.quat_slerp(key[k], key[k + 1], u)
            else:
                out = key[k] + u[:, None] * (key[k + 1] - key[k])
        else:
            u2, u3 = u * u, u * u * u
            out_tangent, in_tangent = self.values[k, 2], self.values[k + 1, 0]
            out = (
                (2 * u3 - 3 * u2 + 1)[:, None] * key[k]
                + ((u3 - 2 * u2 + u) * span)[:, None] * out_tangent
                + (-2 * u3 + 3 * u2)[:, None] * key[k + 1]
                + ((u3 - u2) * span)[:, None] * in_tangent
            )
        return rotations.quat_normalize(out) if self.path == "rotation" else out


def _frame_rate(tracks: list[_Track], start: float, end: float) -> float:
    """The rate of the grid the key times sit on (the closest spacing between two keys of any
    tracks, whole numbers kept whole) when every key is on it and it is at least MIN_GRID_FPS;
    otherwise FALLBACK_FPS, adjusted so that ``end`` falls on a frame."""
    times = np.unique(np.concatenate([tr.times for tr in tracks])) - start
    steps = np.diff(times)
    steps = steps[steps > 0.25 / limits.MAX_FPS]  # keys of two tracks at one time, in float32
    if len(steps):
        rate = 1.0 / float(steps.min())
        if abs(rate - round(rate)) < 1e-3 * rate:
            rate = float(round(rate))
        grid = times * rate
        if rate >= MIN_GRID_FPS and np.abs(grid - np.rint(grid)).max() <= _GRID_SLACK_FRAMES:
            return min(rate, limits.MAX_FPS)
    frames = round((end - start) * FALLBACK_FPS)
    return frames / (end - start) if frames > 0 else FALLBACK_FPS


def _joint_nodes(doc: Document, parents: np.ndarray, moved: set[int]) -> list[int]:
    """The skeleton's nodes, parents first: the first skin's joints, or the moved nodes; with
    every node between them and their common ancestor, and bone tips (childless nodes without
    a mesh) below them."""
    nodes = doc.gltf.nodes
    if doc.gltf.skins:
        joints = doc.gltf.skins[0].joints or []
        for j in joints:
            doc.item(nodes, j, "skin joint")
        wanted = set(joints)
    else:
        wanted = set(moved)
    if not wanted:
        raise doc.fail("no joints: the first skin is empty and the animation moves no node")
    keep = nodetree.closure(parents, wanted)
    if keep is None:
        raise doc.fail("the joints have no common ancestor node (several skeletons in one scene)")
    if not doc.gltf.skins:
        tips = {
            child
            for k in keep
            for child in nodes[k].children or []
            if not nodes[child].children and nodes[child].mesh is None and nodes[child].camera is None
        }
        keep = nodetree.closure(parents, set(keep) | tips) or keep
    return keep


def _mocodec_extras(obj) -> dict:
    extras = getattr(obj, "extras", None)
    value = extras.get("mocodec") if isinstance(extras, dict) else None
    return value if isinstance(value, dict) else {}


def _positive(value, ceiling: float) -> float | None:
    ok = isinstance(value, (int, float)) and not isinstance(value, bool) and 0 < value <= ceiling
    return float(value) if ok else None


def read_gltf(path: str | os.PathLike, *, animation: str | int | None = None, fps: float | None = None) -> Motion:
    """The motion of one animation of a ``.gltf`` or ``.glb`` file (see the module docstring)."""
    path = Path(path)
    doc = _parse(path)
    nodes = doc.gltf.nodes or []
    if not nodes:
        raise doc.fail("no nodes: the file holds no skeleton")
    parents = _tree(doc)
    chosen = _choose_animation(doc, animation)
    tracks: dict[tuple[int, str], _Track] = {}
    for k, channel in enumerate(chosen.channels or []):
        target = channel.target
        if target is None or target.node is None or target.path not in ("translation", "rotation", "scale"):
            continue  # morph weights, or a target of an extension
        doc.item(nodes, target.node, f"channel {k} target node")
        tracks[(target.node, target.path)] = _Track(doc, chosen, channel, k)
    if not tracks:
        raise doc.fail(f"animation {chosen.name or 0!r} moves no node")
    start = min(tr.times[0] for tr in tracks.values())
    end = max(tr.times[-1] for tr in tracks.values())
    stated = _mocodec_extras(doc.gltf.asset)
    rate = fps or _positive(stated.get("fps"), limits.MAX_FPS) or _frame_rate(list(tracks.values()), start, end)
    if not limits.fps_ok(rate):
        raise doc.fail(f"frame rate {rate} out of range {limits.FPS_RANGE}")
    frames = int(round((end - start) * rate)) + 1
    if frames * len(nodes) * 10 > limits.MAX_DECODED_VALUES:
        raise doc.fail(f"{frames} frames of {len(nodes)} nodes: more than one read may decode")
    keep = _joint_nodes(doc, parents, {node for node, _ in tracks})
    needed = nodetree.ancestors(parents, keep[0]) + keep
    units = _positive(stated.get("units_per_metre"), 1e9) or 100.0
    try:
        return _motion(doc, keep, needed, parents, tracks, (start, rate, frames), units, chosen.name or path.stem)
    except ConversionError as e:
        raise doc.fail(str(e)) from None


def _motion(
    doc: Document,
    keep: list[int],
    needed: list[int],
    parents: np.ndarray,
    tracks: dict[tuple[int, str], _Track],
    grid: tuple[float, float, int],
    units_per_metre: float,
    name: str,
) -> Motion:
    """The motion of the joint nodes ``keep``, sampled on ``grid`` (start, rate, frames), in
    ``units_per_metre``."""
    nodes = doc.gltf.nodes
    position, rotation = _world(doc, needed, parents, tracks, grid)
    top = len(needed) - len(keep)
    layouts = [_mocodec_extras(nodes[node]) or None for node in keep]
    names = nodetree.unique_names([str(nodes[node].name or "") for node in keep], keep)
    joints = nodetree.NodeSamples(
        names, nodetree.joint_parents(parents, keep), position[:, top:], rotation[:, top:], layouts
    )
    return nodetree.to_motion(joints, grid[1], units_per_metre, name)


def _world(
    doc: Document,
    needed: list[int],
    parents: np.ndarray,
    tracks: dict[tuple[int, str], _Track],
    grid: tuple[float, float, int],
) -> tuple[np.ndarray, np.ndarray]:
    """World positions and rotations of the nodes ``needed`` (parents first) on the sample
    ``grid`` (start time, rate, frames)."""
    frames, count = grid[2], len(needed)
    translation, rotation, scale = (np.empty((frames, count, w)) for w in (3, 4, 3))
    for k, node in enumerate(needed):
        rest = _rest(doc, node, doc.gltf.nodes[node])
        for array, path, value in zip((translation, rotation, scale), ("translation", "rotation", "scale"), rest):
            track = tracks.get((node, path))
            array[:, k] = track.sample(*grid) if track is not None else value
    index = {node: k for k, node in enumerate(needed)}
    local_parents = np.array([index.get(int(parents[node]), -1) for node in needed], dtype=np.int64)
    return nodetree.world_transforms(local_parents, translation, rotation, scale)

"""A glTF document built by hand, without mocodec's writer: foreign files for the readers' tests."""

from __future__ import annotations

import json
import struct

import numpy as np


class GltfBuilder:
    """A glTF document and its binary chunk, written without mocodec's writer."""

    def __init__(self):
        self.doc: dict = {"asset": {"version": "2.0"}, "nodes": [], "accessors": [], "bufferViews": []}
        self.blob = bytearray()

    def array(self, values, kind: str) -> int:
        data = np.ascontiguousarray(values, dtype="<f4")
        self.blob += b"\0" * (-len(self.blob) % 4)
        self.doc["bufferViews"].append({"buffer": 0, "byteOffset": len(self.blob), "byteLength": data.nbytes})
        self.blob += data.tobytes()
        accessor = {"bufferView": len(self.doc["bufferViews"]) - 1, "componentType": 5126, "count": len(data)}
        self.doc["accessors"].append({**accessor, "type": kind})
        return len(self.doc["accessors"]) - 1

    def animation(self, name: str, tracks: list[tuple[int, str, list, list, str]]) -> None:
        samplers, channels = [], []
        for node, path, times, values, mode in tracks:
            kind = {"translation": "VEC3", "rotation": "VEC4", "scale": "VEC3"}[path]
            sampler = {"input": self.array(times, "SCALAR"), "output": self.array(values, kind), "interpolation": mode}
            self.doc["accessors"][sampler["input"]].update(min=[min(times)], max=[max(times)])
            samplers.append(sampler)
            channels.append({"sampler": len(samplers) - 1, "target": {"node": node, "path": path}})
        self.doc.setdefault("animations", []).append({"name": name, "samplers": samplers, "channels": channels})

    def glb(self) -> bytes:
        self.doc.setdefault("buffers", [{}])[0]["byteLength"] = len(self.blob)
        return glb_bytes(json.dumps(self.doc).encode(), self.blob)


def glb_bytes(text: bytes, blob: bytes) -> bytes:
    """A .glb of the JSON ``text`` (written as it is: it may nest deeper than json.dumps can)
    and the binary chunk ``blob``, each padded to 4 bytes."""
    text += b" " * (-len(text) % 4)
    blob = bytes(blob) + b"\0" * (-len(blob) % 4)
    body = struct.pack("<II", len(text), 0x4E4F534A) + text + struct.pack("<II", len(blob), 0x004E4942) + blob
    return struct.pack("<4sII", b"glTF", 2, 12 + len(body)) + body


def chain_glb(nodes: int) -> GltfBuilder:
    """A glTF of ``nodes`` nodes, each the child of the one before, the first one turning."""
    g = GltfBuilder()
    g.doc["nodes"] = [{"name": f"n{k}", "children": [k + 1], "translation": [0, 0.01, 0]} for k in range(nodes - 1)]
    g.doc["nodes"].append({"name": "end"})
    g.animation("turn", [(0, "rotation", [0, 1], [[0, 0, 0, 1], [0, 0, 0.1, 0.995]], "LINEAR")])
    return g


def trs_matrix(t=(0, 0, 0), q=(0, 0, 0, 1), s=(1, 1, 1)) -> np.ndarray:
    """The 4x4 matrix of a glTF node's translation, rotation ``(x, y, z, w)`` and scale: T R S."""
    x, y, z, w = q
    r = np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )
    m = np.eye(4)
    m[:3, :3] = r * np.asarray(s, float)
    m[:3, 3] = t
    return m

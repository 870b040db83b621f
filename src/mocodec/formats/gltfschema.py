"""The parts of a glTF document mocodec reads and the JSON type each must have
(:data:`SCHEMA`), checked before the document is used (:func:`schema_error`); the document's
objects as attribute dicts (:class:`Fields`) and its integers bounded in length where the JSON
is parsed (:func:`small_int`)."""

from __future__ import annotations

import json

#: The longest integer a glTF document may write (a count or an index; longer ones are refused
#: as the JSON is parsed, before Python converts them).
MAX_INT_DIGITS = 20


class Fields(dict):
    """A JSON object whose fields read as attributes, None where left out (``node.children``)."""

    def __getattr__(self, name: str):
        return self.get(name)


INDEX = "index"
NUMBER = "number"
ANY = "any"
INDICES = [INDEX]
NUMBERS = [NUMBER]
#: The parts of a glTF document mocodec reads, and the JSON type each must have: a field
#: left out is fine, one of another type is refused before the document is used.
SCHEMA = {
    "asset": {"version": str, "extras": ANY},
    "scene": INDEX,
    "scenes": [{"nodes": INDICES}],
    "nodes": [
        {
            "name": str,
            "children": INDICES,
            "translation": NUMBERS,
            "rotation": NUMBERS,
            "scale": NUMBERS,
            "matrix": NUMBERS,
            "mesh": INDEX,
            "camera": INDEX,
            "skin": INDEX,
            "extras": ANY,
        }
    ],
    "skins": [{"joints": INDICES, "skeleton": INDEX, "inverseBindMatrices": INDEX}],
    "animations": [
        {
            "name": str,
            "channels": [{"sampler": INDEX, "target": {"node": INDEX, "path": str}}],
            "samplers": [{"input": INDEX, "output": INDEX, "interpolation": str}],
        }
    ],
    "accessors": [
        {
            "bufferView": INDEX,
            "byteOffset": INDEX,
            "componentType": INDEX,
            "normalized": bool,
            "count": INDEX,
            "type": str,
            "sparse": ANY,
        }
    ],
    "bufferViews": [{"buffer": INDEX, "byteOffset": INDEX, "byteLength": INDEX, "byteStride": INDEX}],
    "buffers": [{"byteLength": INDEX, "uri": str}],
}


def schema_error(value, spec, where: str) -> str | None:
    """Where ``value`` first departs from ``spec`` (see SCHEMA), or None. Iterative: a
    document may nest as deep as it likes."""
    stack = [(value, spec, where)]
    while stack:
        value, spec, where = stack.pop()
        if spec is ANY:
            continue
        if spec is INDEX:
            ok = isinstance(value, int) and not isinstance(value, bool) and value >= 0
            expected = "a non-negative integer"
        elif spec is NUMBER:
            ok = isinstance(value, (int, float)) and not isinstance(value, bool)
            expected = "a number"
        elif isinstance(spec, list):
            ok, expected = isinstance(value, list), "a list"
            if ok:
                stack.extend((item, spec[0], f"{where}[{k}]") for k, item in enumerate(value))
        elif isinstance(spec, dict):
            ok, expected = isinstance(value, dict), "an object"
            if ok:
                stack.extend((value[key], sub, f"{where}.{key}") for key, sub in spec.items() if key in value)
        else:
            ok, expected = (
                isinstance(value, spec) and not isinstance(value, bool) or spec is bool and isinstance(value, bool),
                f"a {spec.__name__}",
            )
        if not ok:
            return f"{where.lstrip('.')}: expected {expected}, got {json.dumps(value)[:40]}"
    return None


def small_int(text: str) -> int:
    """A JSON integer of at most MAX_INT_DIGITS digits (a longer one overflows every float)."""
    if len(text) > MAX_INT_DIGITS:
        raise ValueError(f"an integer of {len(text)} digits ({text[:12]}...): glTF holds none that long")
    return int(text)

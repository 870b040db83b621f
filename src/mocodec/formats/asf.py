"""Acclaim ASF skeletons (reader and writer), with the CMU conventions.

* ``:units length L`` means one file unit is ``0.0254 / L`` metres (CMU: ``length 0.45``, so
  0.056444 m per unit, as in the CMU FAQ); ``angle deg|rad`` applies to ASF values.
* A bone's ``direction * length`` is given in the world frame of the rest pose; its ``axis``
  (angles in the order written after them, e.g. ``XYZ`` = rotate about X, then Y, then Z) is the
  fixed frame ``C`` its ``dof`` rotations act in. ``dof rx ry rz`` rotates about X first, so the
  local rotation is ``Rz Ry Rx``: the rotation order is the dof list reversed (the CMU viewer's
  fixed ``Rz Ry Rx`` for the files it writes). The CMU files list their dofs as ``rx ry rz``.
* In mocodec's skeleton a bone is a pivot at its start (its parent bone's end); a leaf bone's end
  is an end site ``<bone>_end``.
"""

from __future__ import annotations

import os
import re

import numpy as np

from mocodec.errors import ConversionError, FormatError
from mocodec.formats.fileio import atomic_write, parse_number, read_text
from mocodec.skeleton import Joint, Skeleton

INCH = 0.0254
_DOF_CHANNEL = {
    "rx": "Xrotation",
    "ry": "Yrotation",
    "rz": "Zrotation",
    "tx": "Xposition",
    "ty": "Yposition",
    "tz": "Zposition",
}
_CHANNEL_DOF = {v: k for k, v in _DOF_CHANNEL.items()}
_SECTIONS = (":version", ":name", ":units", ":documentation", ":root", ":bonedata", ":hierarchy", ":skin")


# ----------------------------------------------------------------------------- ASF reading
class _AsfParser:
    def __init__(self, path):
        self.path = path
        self.lines = read_text(path).split("\n")
        self.units = {"mass": 1.0, "length": 1.0, "angle": "deg"}
        self.meta: dict = {"documentation": []}
        self.root = {
            "order": ["TX", "TY", "TZ", "RX", "RY", "RZ"],
            "axis": "XYZ",
            "position": (0.0, 0.0, 0.0),
            "orientation": (0.0, 0.0, 0.0),
        }
        self.bones: dict[str, dict] = {}
        self.hierarchy: dict[str, list[str]] = {}
        self.hierarchy_line: dict[str, int] = {}

    def error(self, n: int, message: str) -> FormatError:
        return FormatError(self.path, n + 1, message)

    def numbers(self, n: int, toks: list[str], count: int, what: str) -> tuple[float, ...]:
        if len(toks) < count:
            raise self.error(n, f"{what} needs {count} numbers, found {len(toks)}")
        return tuple(parse_number(t, self.path, n + 1, what) for t in toks[:count])

    def angle(self, value: float) -> float:
        return float(np.rad2deg(value)) if self.units["angle"] == "rad" else value

    def parse(self) -> None:
        section = None
        n = 0
        seen_any = False
        while n < len(self.lines):
            line = self.lines[n].split("#", 1)[0].strip()
            if not line:
                n += 1
                continue
            toks = line.split()
            if toks[0].startswith(":"):
                key = toks[0].lower()
                if key not in _SECTIONS:
                    raise self.error(n, f"unknown section {toks[0]!r}, expected one of {', '.join(_SECTIONS)}")
                section = key
                seen_any = True
                if key in (":version", ":name"):
                    self.meta[key[1:]] = " ".join(toks[1:])
                n += 1
                if key == ":bonedata":
                    n = self._bonedata(n)
                    section = None
                elif key == ":hierarchy":
                    n = self._hierarchy(n)
                    section = None
                continue
            if not seen_any:
                raise self.error(n, f"expected an ASF section such as ':version', found {toks[0]!r}")
            if section == ":units":
                self._unit(n, toks)
            elif section == ":root":
                self._root(n, toks)
            elif section == ":documentation":
                self.meta["documentation"].append(self.lines[n].strip())
            elif section == ":skin":
                pass
            else:
                raise self.error(n, f"unexpected {toks[0]!r} in section {section}")
            n += 1
        if not self.bones and not self.hierarchy:
            raise FormatError(self.path, None, "no :bonedata or :hierarchy section: not an ASF file")
        if not self.hierarchy and self.bones:
            raise FormatError(self.path, None, "missing :hierarchy section")

    def _unit(self, n: int, toks: list[str]) -> None:
        key = toks[0].lower()
        if key not in self.units or len(toks) < 2:
            raise self.error(n, f"unknown unit {toks[0]!r}, expected mass, length or angle with a value")
        if key == "angle":
            value = toks[1].lower()
            if value not in ("deg", "rad"):
                raise self.error(n, f"angle unit {toks[1]!r}, expected deg or rad")
            self.units["angle"] = value
        else:
            self.units[key] = parse_number(toks[1], self.path, n + 1, f"the {key} unit")
            if self.units[key] <= 0:
                raise self.error(n, f"{key} unit must be positive")

    def _root(self, n: int, toks: list[str]) -> None:
        key = toks[0].lower()
        if key == "order":
            order = [t.upper() for t in toks[1:]]
            if (
                not order
                or any(t not in ("TX", "TY", "TZ", "RX", "RY", "RZ") for t in order)
                or len(set(order)) != len(order)
            ):
                raise self.error(n, f"root order {' '.join(toks[1:])!r}, expected distinct TX TY TZ RX RY RZ")
            self.root["order"] = order
        elif key == "axis":
            if len(toks) != 2 or sorted(toks[1].upper()) != ["X", "Y", "Z"]:
                raise self.error(n, "root axis must be an order such as XYZ")
            self.root["axis"] = toks[1].upper()
        elif key in ("position", "orientation"):
            self.root[key] = self.numbers(n, toks[1:], 3, f"root {key}")
        else:
            raise self.error(n, f"unknown root keyword {toks[0]!r}, expected order, axis, position or orientation")

    def _bonedata(self, n: int) -> int:
        bone: dict | None = None
        while n < len(self.lines):
            line = self.lines[n].split("#", 1)[0].strip()
            if not line:
                n += 1
                continue
            toks = line.split()
            key = toks[0].lower()
            continues_limits = line.startswith("(") and bone is not None and bone["in_limits"]
            if bone is not None and key != "limits" and not continues_limits:
                bone["in_limits"] = False
            if key.startswith(":"):
                if bone is not None:
                    raise self.error(n, f"bone {bone.get('name')!r} has no 'end'")
                return n
            if key == "begin":
                if bone is not None:
                    raise self.error(n, "'begin' inside a bone block (missing 'end')")
                bone = {
                    "line": n,
                    "dof": [],
                    "limits": [],
                    "axis": (0.0, 0.0, 0.0),
                    "axis_order": "XYZ",
                    "in_limits": False,
                }
            elif bone is None:
                raise self.error(n, f"{toks[0]!r} outside a begin/end bone block")
            elif key == "end":
                for required in ("name", "direction", "length"):
                    if required not in bone:
                        raise self.error(bone["line"], f"bone block without '{required}'")
                if len(bone["limits"]) not in (0, len(bone["dof"])):
                    raise self.error(
                        n, f"bone {bone['name']!r}: {len(bone['limits'])} limits for {len(bone['dof'])} dofs"
                    )
                if bone["name"] in self.bones or bone["name"] == "root":
                    raise self.error(bone["line"], f"bone name {bone['name']!r} is defined twice")
                self.bones[bone["name"]] = bone
                bone = None
            elif key == "id":
                pass
            elif key == "name":
                if len(toks) != 2:
                    raise self.error(n, "bone name must be one word")
                bone["name"] = toks[1]
            elif key == "direction":
                bone["direction"] = self.numbers(n, toks[1:], 3, "bone direction")
            elif key == "length":
                bone["length"] = self.numbers(n, toks[1:], 1, "bone length")[0]
            elif key == "axis":
                bone["axis"] = tuple(self.angle(v) for v in self.numbers(n, toks[1:], 3, "bone axis"))
                order = toks[4].upper() if len(toks) > 4 else "XYZ"
                if sorted(order) != ["X", "Y", "Z"]:
                    raise self.error(n, f"axis order {order!r}, expected a permutation of XYZ")
                bone["axis_order"] = order
            elif key == "dof":
                dofs = [t.lower() for t in toks[1:]]
                for d in dofs:
                    if d not in _DOF_CHANNEL:
                        raise self.error(n, f"dof {d[:20]!r} is not supported, expected rx, ry, rz, tx, ty or tz")
                if len(set(dofs)) != len(dofs):
                    raise self.error(n, f"dof {' '.join(dofs)}: a dof is listed twice")
                bone["dof"] = dofs
            elif key == "limits" or continues_limits:
                bone["in_limits"] = True
                text = line[len("limits") :] if key == "limits" else line
                pairs = re.findall(r"\(\s*(\S+)\s+(\S+?)\s*\)", text)
                if not pairs:
                    raise self.error(n, "expected limits as (lower upper)")
                for lo, hi in pairs:
                    bone["limits"].append((self._limit(lo, n), self._limit(hi, n)))
            elif key in ("bodymass", "cofmass"):
                pass
            else:
                raise self.error(
                    n,
                    f"unknown bone keyword {toks[0]!r}, expected id, name, direction, length, axis, dof, limits or end",
                )
            n += 1
        if bone is not None:
            raise self.error(n - 1, f"file ends inside bone {bone.get('name')!r}")
        return n

    def _limit(self, token: str, n: int) -> float:
        t = token.lower().lstrip("+")
        if t in ("inf", "-inf"):
            return float(t)
        return self.angle(parse_number(token, self.path, n + 1, "a limit"))

    def _hierarchy(self, n: int) -> int:
        inside = False
        while n < len(self.lines):
            line = self.lines[n].split("#", 1)[0].strip()
            if not line:
                n += 1
                continue
            toks = line.split()
            if toks[0].startswith(":"):
                if inside:
                    raise self.error(n, ":hierarchy has no 'end'")
                return n
            if toks[0].lower() == "begin":
                inside = True
            elif toks[0].lower() == "end":
                return n + 1
            elif not inside:
                raise self.error(n, f"expected 'begin' in :hierarchy, found {toks[0]!r}")
            else:
                for name in toks:
                    if name != "root" and name not in self.bones:
                        raise self.error(n, f"bone {name!r} is not defined in :bonedata")
                parent = toks[0]
                for child in toks[1:]:
                    if child == "root":
                        raise self.error(n, "root cannot be the child of another bone")
                    if child in self.hierarchy_line:
                        raise self.error(n, f"bone {child!r} has two parents")
                    self.hierarchy_line[child] = n
                self.hierarchy.setdefault(parent, []).extend(toks[1:])
            n += 1
        raise self.error(n - 1, ":hierarchy has no 'end'")

    def skeleton(self) -> Skeleton:
        """The skeleton the file describes; FormatError for one the data model refuses."""
        try:
            return self._skeleton()
        except ValueError as e:
            raise FormatError(self.path, None, str(e)) from None

    def _skeleton(self) -> Skeleton:
        root_order = self.root["order"]
        root_rot = [t[1] for t in root_order if t.startswith("R")]
        joints = [
            Joint(
                name="root",
                parent=-1,
                offset=tuple(self.root["position"]),
                channels=tuple(_DOF_CHANNEL[t.lower()] for t in root_order),
                rotation_order="".join(reversed(root_rot)),
                axis=tuple(reversed([self.angle(v) for v in self.root["orientation"]])),
                axis_order=self.root["axis"][::-1],
            )
        ]
        index = {"root": 0}
        bone_vec = {"root": np.zeros(3)}

        todo = [(child, "root") for child in reversed(self.hierarchy.get("root", []))]
        while todo:  # depth first, children in file order (a chain may be thousands deep)
            name, parent = todo.pop()
            b = self.bones[name]
            rot = [d[1].upper() for d in b["dof"] if d.startswith("r")]
            joints.append(
                Joint(
                    name=name,
                    parent=index[parent],
                    offset=tuple(bone_vec[parent]),
                    channels=tuple(_DOF_CHANNEL[d] for d in b["dof"]),
                    rotation_order="".join(reversed(rot)),
                    axis=tuple(reversed(b["axis"])),
                    axis_order=b["axis_order"][::-1],
                    limits=tuple(b["limits"]),
                )
            )
            index[name] = len(joints) - 1
            bone_vec[name] = np.asarray(b["direction"]) * b["length"]
            kids = self.hierarchy.get(name, [])
            if not kids:
                if f"{name}_end" in self.bones:
                    raise self.error(
                        self.bones[f"{name}_end"]["line"],
                        f"bone name {name}_end is the name of the end site of leaf bone {name!r}",
                    )
                joints.append(Joint(name=f"{name}_end", parent=index[name], offset=tuple(bone_vec[name])))
            todo.extend((child, name) for child in reversed(kids))
        missing = [name for name in self.bones if name not in index]
        if missing:
            raise self.error(
                self.hierarchy_line.get(missing[0], self.bones[missing[0]]["line"]),
                f"bone {missing[0]!r} is not connected to the root in :hierarchy",
            )
        meta = {
            "asf_name": self.meta.get("name", ""),
            "asf_version": self.meta.get("version", "1.10"),
            "mass": self.units["mass"],
            "documentation": self.meta["documentation"],
        }
        return Skeleton(
            tuple(joints), units_per_metre=self.units["length"] / INCH, name=meta["asf_name"], metadata=meta
        )


def read_asf(path: str | os.PathLike) -> Skeleton:
    """Read an ASF skeleton."""
    parser = _AsfParser(path)
    parser.parse()
    return parser.skeleton()


# ----------------------------------------------------------------------------- writing
def asf_bone_vectors(skeleton: Skeleton) -> dict[int, np.ndarray]:
    """Every bone's vector (the common offset of its children), or ConversionError."""
    vectors: dict[int, np.ndarray] = {}
    for i, j in enumerate(skeleton.joints):
        kids = skeleton.children[i]
        if i > 0 and any(c.endswith("position") for c in j.channels):
            raise ConversionError(f"joint {j.name!r} has translation channels; ASF bones can only rotate")
        if i > 0 and skeleton.end_sites[i]:
            continue
        if j.rotation_order != "".join(reversed([c[0] for c in j.channels if c.endswith("rotation")])):
            raise ConversionError(
                f"joint {j.name!r}: rotation order {j.rotation_order!r} is not its dof list "
                "reversed; use mocodec.convert.to_asf_form first"
            )
        offs = skeleton.offsets[list(kids)] if kids else np.zeros((1, 3))
        if i == 0:
            if np.abs(offs).max() > 1e-9:
                raise ConversionError(
                    "bones attached to the ASF root must start at the root; use mocodec.convert.to_asf_form first"
                )
            continue
        if np.abs(offs - offs[0]).max() > 1e-9:
            raise ConversionError(
                f"joint {j.name!r}: its children start at different points; use mocodec.convert.to_asf_form first"
            )
        vectors[i] = offs[0]
    return vectors


def _fmt(v: float) -> str:
    s = f"{v:.6g}"
    return "0" if s == "-0" else s


def asf_text(skeleton: Skeleton) -> str:
    """The ASF text of a skeleton in ASF form (see :func:`mocodec.convert.to_asf_form`)."""
    vectors = asf_bone_vectors(skeleton)
    meta = skeleton.metadata
    root = skeleton.joints[0]
    out = [
        "# ASF file written by mocodec",
        f":version {meta.get('asf_version', '1.10')}",
        f":name {meta.get('asf_name') or skeleton.name or 'mocodec'}",
        ":units",
        f"  mass {_fmt(meta.get('mass', 1.0))}",
        f"  length {skeleton.units_per_metre * INCH:.10g}",
        "  angle deg",
        ":documentation",
        *[f"   {line}" for line in meta.get("documentation", [])],
        ":root",
        f"   order {' '.join(_CHANNEL_DOF[c].upper() for c in root.channels)}",
        f"   axis {root.axis_order[::-1]}",
        f"   position {' '.join(_fmt(v) for v in root.offset)}",
        f"   orientation {' '.join(_fmt(v) for v in reversed(root.axis))}",
        ":bonedata",
    ]
    for bone_id, (i, vec) in enumerate(vectors.items(), start=1):
        j = skeleton.joints[i]
        length = float(np.linalg.norm(vec))
        direction = vec / length if length > 0 else np.array([0.0, 0.0, 1.0])
        out += [
            "  begin",
            f"     id {bone_id}",
            f"     name {j.name}",
            f"     direction {' '.join(f'{v:.9g}' for v in direction)}",
            f"     length {length:.9g}",
            f"     axis {' '.join(_fmt(v) for v in reversed(j.axis))} {j.axis_order[::-1]}",
        ]
        if j.channels:
            out.append(f"    dof {' '.join(_CHANNEL_DOF[c] for c in j.channels)}")
            lims = [f"({_fmt(lo)} {_fmt(hi)})" for lo, hi in j.limits]
            out.append(f"    limits {lims[0]}")
            out += [f"           {lim}" for lim in lims[1:]]
        out.append("  end")
    out += [":hierarchy", "  begin"]
    for i in [0, *vectors]:
        kids = [skeleton.names[c] for c in skeleton.children[i] if c in vectors]
        if kids:
            out.append(f"    {'root' if i == 0 else skeleton.names[i]} {' '.join(kids)}")
    out.append("  end")
    return "\n".join(out) + "\n"


def write_asf(skeleton: Skeleton, path: str | os.PathLike) -> None:
    """Write an ASF skeleton atomically."""
    atomic_write(path, asf_text(skeleton))

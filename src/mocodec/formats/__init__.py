"""Reading and writing motion files: BVH, ASF/AMC, glTF and FBX, chosen by file extension."""

from __future__ import annotations

import os
from pathlib import Path

from mocodec.errors import ConversionError, FormatError
from mocodec.formats.amc import CMU_FPS, find_asf, read_amc, write_amc
from mocodec.formats.asf import read_asf, write_asf
from mocodec.formats.bvh import guess_units_per_metre, read_bvh, write_bvh
from mocodec.formats.convert import to_asf_form, to_bvh_form, with_units
from mocodec.formats.fbx import read_fbx
from mocodec.formats.gltf import read_gltf
from mocodec.formats.gltfwrite import write_gltf
from mocodec.motion import Motion

READABLE = (".bvh", ".amc", ".gltf", ".glb", ".fbx")
WRITABLE = (".bvh", ".amc", ".gltf", ".glb")


def load(
    path: str | os.PathLike,
    *,
    asf: str | os.PathLike | None = None,
    fps: float | None = None,
    units_per_metre: float | None = None,
    animation: str | int | None = None,
) -> Motion:
    """Read a ``.bvh``, ``.amc``, ``.gltf``/``.glb`` or ``.fbx`` file (the ASF is found beside
    an AMC unless given).

    ``fps`` sets the rate of an AMC (default 120, the CMU rate), overrides a BVH's ``Frame
    Time``, and is the rate a glTF or FBX animation is sampled at (default: the file's own);
    ``units_per_metre`` overrides a BVH's stated or guessed unit; ``animation`` picks a glTF animation or
    an FBX take by name or index (the first by default).
    """
    path = Path(path)
    ext = path.suffix.lower()
    if ext == ".bvh":
        motion = read_bvh(path, units_per_metre=units_per_metre)
        return motion if fps is None else Motion(motion.skeleton, fps, motion.channels)
    if ext == ".amc":
        return read_amc(path, asf, fps=CMU_FPS if fps is None else fps)
    if ext in (".gltf", ".glb"):
        return read_gltf(path, animation=animation, fps=fps)
    if ext == ".fbx":
        return read_fbx(path, animation=animation, fps=fps)
    if ext == ".asf":
        raise FormatError(path, None, "an ASF file holds a skeleton only; load its .amc motion instead")
    expected = ", ".join(READABLE)
    raise FormatError(path, None, f"unknown file type {path.suffix or '(none)'!r}, expected one of {expected}")


def save(
    motion: Motion, path: str | os.PathLike, *, asf: str | os.PathLike | None = None, mesh: str | None = None
) -> list[Path]:
    """Write ``motion`` as ``.bvh``, ``.amc`` (plus its ``.asf``, by default beside it with the
    same stem) or ``.gltf``/``.glb`` (with ``mesh="mannequin"`` a skinned body too:
    :mod:`mocodec.mannequin`), converting the skeleton form as needed; returns the files
    written.

    A BVH is written in the skeleton's unit when a reader would guess it from the skeleton's
    size, else in centimetres (e.g. CMU ASF units), stating the unit when even that would be
    misread (:mod:`mocodec.formats.bvh`)."""
    path = Path(path)
    ext = path.suffix.lower()
    if mesh is not None and ext not in (".gltf", ".glb"):
        raise ConversionError(f"{path}: a mesh is written to .gltf or .glb only, not {path.suffix or 'no extension'}")
    check_writable(path)
    if ext == ".bvh":
        bvh_motion = to_bvh_form(motion)
        if guess_units_per_metre(bvh_motion.skeleton.span()) != bvh_motion.skeleton.units_per_metre:
            bvh_motion = with_units(bvh_motion, 100.0)  # the unit most readers assume
        write_bvh(bvh_motion, path)
        return [path]
    if ext == ".amc":
        asf_path = Path(asf) if asf is not None else path.with_suffix(".asf")
        write_amc(to_asf_form(motion), path, asf_path)
        return [asf_path, path]
    write_gltf(motion, path, mesh=mesh)  # (.gltf or .glb: check_writable let no other through)
    return [path]


def check_writable(path: str | os.PathLike) -> Path:
    """``path``, if :func:`save` writes its kind of file, else ConversionError (a command that
    records or converts for long checks before it starts)."""
    path = Path(path)
    if path.suffix.lower() not in WRITABLE:
        expected = ", ".join(WRITABLE)
        raise ConversionError(f"{path}: cannot write {path.suffix or 'files without extension'}, expected {expected}")
    return path


__all__ = [
    "load",
    "save",
    "check_writable",
    "read_bvh",
    "write_bvh",
    "read_asf",
    "write_asf",
    "read_amc",
    "write_amc",
    "find_asf",
    "to_asf_form",
    "to_bvh_form",
    "with_units",
    "read_gltf",
    "write_gltf",
    "read_fbx",
    "READABLE",
    "WRITABLE",
]

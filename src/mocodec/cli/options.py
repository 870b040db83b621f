"""Options several commands share: the input options of .amc files, the skeleton of a .moc file
coded without one, the codec and its knobs, and a rate-control target. Light to import: every
command's parser uses them."""

from __future__ import annotations

import argparse
import math

from mocodec.codecs.registry import DEFAULT_CODEC
from mocodec.errors import CodecError


def skeleton_from(path: str | None):
    """The skeleton of an .asf file, or of a motion file (.bvh, .amc, .gltf, .glb, .fbx); None for no path."""
    if path is None:
        return None
    if path.lower().endswith(".asf"):
        from mocodec.formats.asf import read_asf

        return read_asf(path)
    from mocodec.formats import load

    return load(path).skeleton


def add_input_options(p) -> None:
    p.add_argument("--asf", help="ASF skeleton of an .amc input (default: <subject>.asf beside it)")
    p.add_argument(
        "--fps",
        type=float,
        help="frame rate of an .amc input (default 120, the CMU rate), or to sample a glTF/FBX animation at "
        "(default: the file's own)",
    )
    p.add_argument(
        "--animation", metavar="NAME|INDEX", help="the glTF animation or FBX take to read (default: the first)"
    )
    p.add_argument(
        "--units",
        type=units_per_metre,
        metavar="UNIT",
        help="length unit of a .bvh input: m, cm, mm, in, or units per metre "
        "(default: the unit the file states, else guessed from the skeleton's size)",
    )


#: Names of length units, as units per metre.
UNIT_NAMES = {"m": 1.0, "cm": 100.0, "mm": 1000.0, "in": 1.0 / 0.0254}


def units_per_metre(text: str) -> float:
    """``--units``: a unit's name or a positive number of units per metre."""
    import argparse
    import math

    if text.lower() in UNIT_NAMES:
        return UNIT_NAMES[text.lower()]
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and value > 0):
        names = ", ".join(UNIT_NAMES)
        raise argparse.ArgumentTypeError(f"{text!r} is not a unit ({names}) or a positive number of units per metre")
    return value


def load_input(path, args):
    """The motion file ``path`` read with the input options of ``args``."""
    from mocodec.formats import load

    return load(
        path,
        asf=args.asf,
        fps=args.fps,
        animation=getattr(args, "animation", None),
        units_per_metre=getattr(args, "units", None),
    )


TARGET_OPTIONS = (
    ("ratio", "ratio", "compression ratio vs 32-bit floats, e.g. 50"),
    ("bitrate", "bitrate", "bits per second"),
    ("psnr", "psnr", "whole-body PSNR in dB (mean over DOFs)"),
    ("mean-error-cm", "mean_error_cm", "mean joint position error bound in cm"),
    ("max-error-cm", "max_error_cm", "max joint position error bound in cm (guaranteed)"),
)


def add_codec_options(p, default: str = DEFAULT_CODEC) -> None:
    p.add_argument("--codec", default=default, help=f"codec id (default {default}; see `mocodec codecs`)")
    group = p.add_mutually_exclusive_group()
    for flag, dest, text in TARGET_OPTIONS:
        group.add_argument(f"--{flag}", dest=dest, type=float, help=text)


def knobs_from(extra: list[str]) -> dict[str, str]:
    """``--name value`` pairs left over by argparse, as codec knobs."""
    knobs, k = {}, 0
    while k < len(extra):
        flag = extra[k]
        if not flag.startswith("--") or k + 1 >= len(extra):
            raise CodecError(f"unexpected argument {flag!r} (codec knobs are given as --name value)")
        name, _, value = flag[2:].partition("=")
        if not value:
            value, k = extra[k + 1], k + 1
        knobs[name.replace("-", "_")] = value
        k += 1
    return knobs


def target_of(args) -> tuple[str, float] | None:
    """The rate-control target given on the command line, as (name, value), or None."""
    return next(((dest, getattr(args, dest)) for _, dest, _ in TARGET_OPTIONS if getattr(args, dest) is not None), None)


def rate_text(size_bytes: float, seconds: float) -> str:
    """The bit rate of ``size_bytes`` over ``seconds`` as the command line prints it ("no
    frames" for a clip of none, which has no rate)."""
    return f"{size_bytes * 8 / seconds / 1000:.2f} kbit/s" if seconds > 0 else "no frames"


def number_in(kind: type, low: float, high: float = math.inf, above: bool = False):
    """An argparse type: a ``kind`` (int or float) from ``low`` (exclusive with ``above``) to
    ``high``, else a one-line usage error that says the range (a port of 99999 or a tick rate
    of 0 reached the server as a traceback)."""

    def parse(text: str):
        try:
            value = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not {'an integer' if kind is int else 'a number'}") from None
        if not ((value > low if above else value >= low) and value <= high):  # (NaN fails both)
            where = f"above {low:g}" if above else f"at least {low:g}"
            raise argparse.ArgumentTypeError(
                f"{text} is out of range: {where}" + (f", at most {high:g}" if high < math.inf else "")
            )
        return value

    return parse


PORT = number_in(int, 0, 65535)  # a TCP port (0: any free one)

"""The coding commands of the CLI: ``encode``, ``decode``, ``eval``, ``truncate`` and ``codecs``.

Codec knobs are given as options named after them (``--levels 64`` for the knob ``levels``);
``--ratio``, ``--bitrate``, ``--psnr``, ``--mean-error-cm`` and ``--max-error-cm`` ask rate
control for the knob instead.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

from mocodec import limits, moc, ratecontrol
from mocodec.cli.options import (
    add_codec_options,
    add_input_options,
    load_input,
    rate_text,
    skeleton_from,
    target_of,
)
from mocodec.codecs import codec_class, codec_ids, get_codec
from mocodec.errors import CodecError
from mocodec.formats import READABLE, save
from mocodec.formats.fileio import atomic_write_bytes, one_source_each
from mocodec.metrics import compare
from mocodec.metrics.compare import db_text
from mocodec.motion import Motion


def configured(args, motion: Motion):
    """The codec of the command line, tuned by rate control if a target was given:
    (codec, measurement or None). A target the codec guarantees itself sets its knob: nothing is
    searched or measured."""
    codec = get_codec(args.codec, **args.knobs)
    target = target_of(args)
    if target is None:
        return codec, None
    bound = ratecontrol.guaranteed(codec, *target)
    if bound is not None:
        return bound, None
    m = ratecontrol.tune(codec, motion, *target)
    return m.codec, m


def _progress(k: int, n: int, text: str) -> None:
    if n > 1:
        print(f"[{k}/{n}] {text}", file=sys.stderr, flush=True)


def cmd_encode(args) -> int:
    inputs = [Path(p) for p in args.inputs]
    out = Path(args.output)
    if len(inputs) > 1 and not out.is_dir():
        raise CodecError(f"{out}: with several inputs, -o must be an existing directory")
    if not out.is_dir():
        moc_name(out)
    targets = [out / f"{src.stem}.moc" if out.is_dir() else out for src in inputs]
    one_source_each(zip(inputs, targets))
    for k, (src, target) in enumerate(zip(inputs, targets), 1):
        motion = load_input(src, args)
        codec, _ = configured(args, motion)
        t0 = time.perf_counter()
        size = moc.encode(
            motion,
            target,
            codec,
            chunk_frames=args.chunk_frames,
            embed_skeleton=not args.skeleton_ref,
            exact_skeleton=args.exact_skeleton,
            jobs=args.jobs,
        )
        line = (
            f"{target}: {motion.num_frames} frames, {size:,} bytes, ratio {motion.raw_bits / 8 / size:.2f} "
            f"vs 32-bit floats, {rate_text(size, motion.duration)}, {codec!r}, {time.perf_counter() - t0:.2f} s"
        )
        _progress(k, len(inputs), src.name)
        print(line)
    return 0


def moc_name(path: Path) -> None:
    """CodecError where ``path`` is named as a motion file (.bvh, .asf, ...): a coded file
    written there replaced the clip itself (``encode clip.bvh -o clip.bvh``)."""
    if path.suffix.lower() in (*READABLE, ".asf"):
        raise CodecError(f"{path}: a coded file would replace a motion file there; name it .moc")


def parse_frames(text: str | None) -> tuple[int, int] | None:
    if text is None:
        return None
    a, sep, b = text.partition(":")
    try:
        if not sep:
            raise ValueError
        return int(a or 0), int(b) if b else -1
    except ValueError:
        raise CodecError(f"--frames wants FIRST:STOP (e.g. 120:240), got {text!r}") from None


def cmd_decode(args) -> int:
    skeleton = skeleton_from(args.skeleton)
    frames = parse_frames(args.frames)
    if frames and frames[1] == -1:
        frames = (frames[0], moc.info(args.input, skeleton).frames)
    files = {
        name: path for name, path in (("codebook", args.codebook), ("db", args.db), ("tables", args.tables)) if path
    }
    motion = moc.decode(args.input, frames=frames, skeleton=skeleton, local_files=files, max_values=args.max_values)
    written = save(motion, args.output, asf=args.out_asf)
    print(f"wrote {', '.join(str(p) for p in written)} ({motion.num_frames} frames)")
    return 0


def cmd_truncate(args) -> int:
    moc_name(Path(args.output))
    data = Path(args.input).read_bytes()
    skeleton = skeleton_from(args.skeleton)
    out = moc.truncate(data, ratio=args.ratio, bitrate=args.bitrate, name=args.input, skeleton=skeleton)
    atomic_write_bytes(args.output, out)
    info = moc.info(args.output, skeleton)
    raw = info.frames * info.skeleton.num_channels * 4
    print(
        f"{args.output}: {len(out):,} bytes (was {len(data):,}), ratio {raw / len(out):.2f} vs 32-bit floats, "
        f"{rate_text(len(out), info.frames / info.fps)}"
    )
    return 0


# the excerpt that compiles (or loads) a codec's kernels before it is timed: long enough for
# every step of a clip's coding (kinwave places its wavelet grid from 70 frames on), so the
# timed round trip loads none
FIRST_USE_FRAMES = 128


def evaluate(motion: Motion, args) -> str:
    """Encode and decode in memory; the table of ``eval``."""
    if not motion.skeleton.num_channels:
        raise CodecError("nothing to evaluate: the clip has no channels (a rig whose joints never move)")
    codec, _ = configured(args, motion)
    t0 = time.perf_counter()
    moc.round_trip(motion[:FIRST_USE_FRAMES], codec)  # compiles (or loads) the codec's kernels
    first_use = time.perf_counter() - t0
    trip = moc.round_trip(motion, codec)
    data = trip.data
    s = compare(motion, trip.decoded).summary()
    us = 1e6 / max(motion.num_frames, 1)
    rows = [
        ("codec", repr(codec)),
        ("size", f"{len(data):,} bytes for {motion.num_frames} frames ({motion.duration:.2f} s)"),
        ("ratio", f"{motion.raw_bits / 8 / len(data):.2f} : 1 vs 32-bit floats"),
        (
            "bit rate",
            f"{rate_text(len(data), motion.duration)} ({len(data) * 8 / motion.channels.size:.3f} bits per DOF sample)",
        ),
        ("PSNR / VPSNR", f"{db_text(s['psnr_db'])} / {db_text(s['vpsnr_db'])} (mean over DOFs)"),
        ("joint error mean / max", f"{s['mean_joint_error_cm']:.4g} / {s['max_joint_error_cm']:.4g} cm"),
        ("shell error max", f"{s['max_shell_error_cm']:.4g} cm"),
        ("encode / decode", f"{trip.encode_s * us:.1f} / {trip.decode_s * us:.1f} us per frame"),
        (
            "first use",
            f"{first_use:.2f} s (compiling the kernels, or loading them from the cache; "
            "`mocodec warmup` does it once per install)",
        ),
    ]
    if codec.variable_delay:
        wait = codec.delays(motion) / motion.fps
        rows.append(("coding delay mean / max", f"{wait.mean():.2f} / {wait.max():.2f} s"))
    return "\n".join(f"{k:<24}{v}" for k, v in rows)


def cmd_eval(args) -> int:
    inputs = args.inputs
    for k, path in enumerate(inputs, 1):
        motion = load_input(path, args)
        _progress(k, len(inputs), Path(path).name)
        print(f"{'file':<24}{path}")
        print(evaluate(motion, args))
        if k < len(inputs):
            print()
    return 0


def cmd_codecs(args) -> int:
    """One codec a line, its id in the first column (padded to the longest), then its
    description; its knobs, quality knob, delay and flags on the next line, indented."""
    ids = codec_ids()
    width = max(map(len, ids)) + 2
    for cid in ids:
        cls = codec_class(cid)
        flags = ", ".join(
            f
            for f, on in (
                ("lossless", cls.lossless),
                ("streaming", cls.streaming),
                ("embedded", cls.embedded),
                ("baseline for comparison", cls.baseline),
            )
            if on
        )
        knobs = " ".join(k.describe() for k in cls.knobs) or "-"
        quality = f"; quality knob {cls.quality.name}" if cls.quality else ""
        print(f"{cid:<{width}}{cls.description}")
        delay = "variable (per frame: codec.delays(motion))" if cls.variable_delay else f"{cls().delay_frames()} frames"
        print(f"{'':<{width}}knobs: {knobs}{quality}; delay {delay}{'; ' + flags if flags else ''}")
    return 0


def add_commands(sub) -> None:
    p = sub.add_parser(
        "encode",
        description="Code each input into a .moc container. Codec knobs are options named "
        "after them (--name value); a target (--ratio, --bitrate, --psnr, "
        "--mean-error-cm, --max-error-cm) makes rate control choose the knob.",
    )
    p.add_argument("inputs", nargs="+", metavar="IN", help="motion file(s): .bvh, .amc, .gltf, .glb or .fbx")
    p.add_argument("-o", "--output", required=True, help="output .moc file, or a directory for several inputs")
    p.add_argument(
        "--chunk-frames",
        type=int,
        default=moc.CHUNK_FRAMES,
        help=f"frames per independently decodable chunk (default {moc.CHUNK_FRAMES})",
    )
    p.add_argument(
        "--skeleton-ref",
        action="store_true",
        help="store only the skeleton's id (1-2 KB smaller); decoding then needs --skeleton",
    )
    p.add_argument(
        "--exact-skeleton",
        action="store_true",
        help="keep the skeleton's offsets bit for bit (a lossy codec's file rounds them to "
        f"{moc.SKELETON_PRECISION_CM:g} cm, which saves 130-360 bytes on CMU skeletons)",
    )
    p.add_argument(
        "--jobs",
        type=int,
        default=1,
        help="processes coding a file's chunks at once (default 1; the same bytes whatever the number)",
    )
    add_codec_options(p)
    add_input_options(p)
    p.set_defaults(func=cmd_encode, takes_knobs=True)

    p = sub.add_parser("decode", description="Decode a .moc file (only the chunks --frames needs) and write it.")
    p.add_argument("input", metavar="IN", help=".moc file")
    p.add_argument("-o", "--output", required=True, help="motion file to write: .bvh, .amc, .gltf or .glb")
    p.add_argument("--frames", help="FIRST:STOP, a frame range (e.g. 120:240)")
    p.add_argument("--skeleton", help="the skeleton (.asf, .bvh or .amc) of a file encoded with --skeleton-ref")
    p.add_argument("--out-asf", help="where to write the ASF when the output is .amc")
    p.add_argument(
        "--codebook",
        help="the VQ codebook file (svq, tvq) the file was coded with; a file never "
        "names what is opened, the body's fingerprint is checked against it",
    )
    p.add_argument("--db", help="the primitive or rhythm database (primitives, rhythmic) the file was coded with")
    p.add_argument("--tables", help="the motion tables (posture, gesture) the file was coded with")
    p.add_argument(
        "--max-values",
        type=int,
        default=limits.MAX_DECODED_VALUES,
        help=f"refuse to decode more than this many values, frames x channels (default "
        f"{limits.MAX_DECODED_VALUES:,}: a damaged file cannot exhaust memory)",
    )
    p.set_defaults(func=cmd_decode)

    p = sub.add_parser(
        "eval",
        description="Ratio vs 32-bit floats, bits per second, PSNR, VPSNR, mean/max joint "
        "error (cm), encode and decode time per frame.",
    )
    p.add_argument("inputs", nargs="+", metavar="IN", help="motion file(s): .bvh, .amc, .gltf, .glb or .fbx")
    add_codec_options(p)
    add_input_options(p)
    p.set_defaults(func=cmd_eval, takes_knobs=True)

    p = sub.add_parser(
        "truncate",
        description="Every channel stream of an embedded file is cut to the prefix a smaller "
        "budget allows; the result decodes to a coarser motion.",
    )
    p.add_argument("input", metavar="IN", help=".moc file coded by an embedded codec (spiht)")
    p.add_argument("-o", "--output", required=True, help=".moc file to write")
    target = p.add_mutually_exclusive_group(required=True)
    target.add_argument("--ratio", type=float, help="compression ratio vs 32-bit floats")
    target.add_argument("--bitrate", type=float, help="bits per second")
    p.add_argument("--skeleton", help="the skeleton (.asf, .bvh or .amc) of a file encoded with --skeleton-ref")
    p.set_defaults(func=cmd_truncate)

    p = sub.add_parser("codecs")
    p.set_defaults(func=cmd_codecs)

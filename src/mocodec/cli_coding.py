"""The coding commands of the CLI: ``encode``, ``decode``, ``eval``, ``codecs``, and the model
trainers ``codebook``, ``primitives``, ``rhythm`` and ``tables``.

Codec knobs are given as options named after them (``--levels 64`` for the knob ``levels``);
``--ratio``, ``--bitrate``, ``--psnr``, ``--mean-error-cm`` and ``--max-error-cm`` ask rate
control for the knob instead.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

from mocodec import limits, moc, ratecontrol
from mocodec.codecs import DEFAULT_CODEC, codec_class, codec_ids, get_codec
from mocodec.coding import motiontables, primdb, rhythmdb, segmentation, vqbook
from mocodec.errors import CodecError
from mocodec.formats import load, save
from mocodec.formats._io import atomic_write_bytes
from mocodec.metrics import compare
from mocodec.motion import Motion

TARGET_OPTIONS = (("ratio", "ratio", "compression ratio vs 32-bit floats, e.g. 50"),
                  ("bitrate", "bitrate", "bits per second"),
                  ("psnr", "psnr", "whole-body PSNR in dB (mean over DOFs)"),
                  ("mean-error-cm", "mean_error_cm", "mean joint position error bound in cm"),
                  ("max-error-cm", "max_error_cm", "max joint position error bound in cm (guaranteed)"))


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
    return next(((dest, getattr(args, dest)) for _, dest, _ in TARGET_OPTIONS if getattr(args, dest) is not None),
                None)


def configured(args, motion: Motion):
    """The codec of the command line, tuned by rate control if a target was given:
    (codec, measurement or None)."""
    codec = get_codec(args.codec, **args.knobs)
    target = target_of(args)
    if target is None:
        return codec, None
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
    for k, src in enumerate(inputs, 1):
        motion = load(src, asf=args.asf, fps=args.fps)
        codec, _ = configured(args, motion)
        target = out / f"{src.stem}.moc" if out.is_dir() else out
        t0 = time.perf_counter()
        size = moc.encode(motion, target, codec, chunk_frames=args.chunk_frames, embed_skeleton=not args.skeleton_ref,
                          exact_skeleton=args.exact_skeleton)
        line = (f"{target}: {motion.num_frames} frames, {size:,} bytes, ratio {motion.raw_bits / 8 / size:.2f} "
                f"vs 32-bit floats, {size * 8 / motion.duration / 1000:.2f} kbit/s, {codec!r}, "
                f"{time.perf_counter() - t0:.2f} s")
        _progress(k, len(inputs), src.name)
        print(line)
    return 0


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


def skeleton_from(path: str | None):
    """The skeleton of an .asf file, or of a .bvh or .amc motion file; None for no path."""
    if path is None:
        return None
    if Path(path).suffix.lower() == ".asf":
        from mocodec.formats.asf_amc import read_asf

        return read_asf(path)
    return load(path).skeleton


def cmd_decode(args) -> int:
    skeleton = skeleton_from(args.skeleton)
    frames = parse_frames(args.frames)
    if frames and frames[1] == -1:
        frames = (frames[0], moc.info(args.input, skeleton).frames)
    files = {name: path for name, path in (("codebook", args.codebook), ("db", args.db), ("tables", args.tables))
             if path}
    motion = moc.decode(args.input, frames=frames, skeleton=skeleton, local_files=files, max_values=args.max_values)
    written = save(motion, args.output, asf=args.out_asf)
    print(f"wrote {', '.join(str(p) for p in written)} ({motion.num_frames} frames)")
    return 0


def cmd_truncate(args) -> int:
    data = Path(args.input).read_bytes()
    skeleton = skeleton_from(args.skeleton)
    out = moc.truncate(data, ratio=args.ratio, bitrate=args.bitrate, name=args.input, skeleton=skeleton)
    atomic_write_bytes(args.output, out)
    info = moc.info(args.output, skeleton)
    raw = info.frames * info.skeleton.num_channels * 4
    print(f"{args.output}: {len(out):,} bytes (was {len(data):,}), ratio {raw / len(out):.2f} vs 32-bit floats, "
          f"{len(out) * 8 * info.fps / max(info.frames, 1) / 1000:.2f} kbit/s")
    return 0


def evaluate(motion: Motion, args) -> str:
    """Encode and decode in memory; the table of ``eval``."""
    codec, _ = configured(args, motion)
    trip = moc.round_trip(motion, codec)
    data = trip.data
    s = compare(motion, trip.decoded).summary()
    us = 1e6 / max(motion.num_frames, 1)
    rows = [
        ("codec", repr(codec)),
        ("size", f"{len(data):,} bytes for {motion.num_frames} frames ({motion.duration:.2f} s)"),
        ("ratio", f"{motion.raw_bits / 8 / len(data):.2f} : 1 vs 32-bit floats"),
        ("bit rate", f"{len(data) * 8 / motion.duration / 1000:.2f} kbit/s "
                     f"({len(data) * 8 / motion.channels.size:.3f} bits per DOF sample)"),
        ("PSNR / VPSNR", f"{_db(s['psnr_db'])} / {_db(s['vpsnr_db'])} (mean over DOFs)"),
        ("joint error mean / max", f"{s['mean_joint_error_cm']:.4g} / {s['max_joint_error_cm']:.4g} cm"),
        ("shell error max", f"{s['max_shell_error_cm']:.4g} cm"),
        ("encode / decode", f"{trip.encode_s * us:.1f} / {trip.decode_s * us:.1f} us per frame"),
    ]
    if codec.variable_delay:
        wait = codec.delays(motion) / motion.fps
        rows.append(("coding delay mean / max", f"{wait.mean():.2f} / {wait.max():.2f} s"))
    return "\n".join(f"{k:<24}{v}" for k, v in rows)


def _db(x: float) -> str:
    return f"{x:.2f} dB" if x != float("inf") else "lossless"


def _training_clips(args) -> list[Motion]:
    """The clips a train command names, loaded with progress."""
    clips = []
    for k, path in enumerate(args.inputs, 1):
        _progress(k, len(args.inputs), Path(path).name)
        clips.append(load(path, asf=args.asf, fps=args.fps))
    return clips


def cmd_codebook(args) -> int:
    if args.action == "info":
        for path in args.inputs:
            book = vqbook.Codebook.load(path)
            print(f"{path}: {book.kind}, {'predictive' if book.predictive else 'plain'}, length {book.length}, "
                  f"{book.fps:g} Hz, sizes {sorted(book.books)}, groups {', '.join(n for n, _ in book.groups)}, "
                  f"trained on {len(book.trained_on)} clips")
        return 0
    if not args.output:
        raise CodecError("codebook train needs -o FILE")
    if args.max_size < 16 or args.max_size & (args.max_size - 1):
        raise CodecError(f"--max-size must be a power of two >= 16, got {args.max_size}")
    clips = [clip.resample(args.rate) for clip in _training_clips(args)]
    sizes = [1 << k for k in range(4, args.max_size.bit_length())]
    book = vqbook.train(args.kind, clips, sizes, predictive=not args.plain, length=args.length,
                        names=[Path(p).name for p in args.inputs])
    book.save(args.output)
    print(f"wrote {args.output}: {args.kind} codebook, sizes {sizes}, {Path(args.output).stat().st_size:,} bytes")
    return 0


def cmd_primitives(args) -> int:
    if args.action == "info":
        for path in args.inputs:
            db = primdb.PrimitiveDB.load(path)
            worst = max(db.errors.values(), default=0.0)
            print(f"{path}: {db.count} primitives for {len(db.primitives)} joints, {Path(path).stat().st_size:,} bytes, "
                  f"{db.fps:g} Hz, S_M {db.max_segment}, seed {db.seed}, largest clustering error {worst:.3f} rad, "
                  f"fingerprint {db.fingerprint:08x}, trained on {', '.join(db.trained_on) or '?'}")
        return 0
    if not args.output:
        raise CodecError("primitives train needs -o FILE")
    clips = _training_clips(args)
    t0 = time.perf_counter()
    db = primdb.train(clips, max_segment=args.max_segment, seed=args.seed, threshold=args.threshold,
                      max_clusters=args.max_clusters, names=[Path(p).name for p in args.inputs])
    db.save(args.output)
    print(f"wrote {args.output}: {db.count} primitives for {len(db.primitives)} joints from "
          f"{sum(db.segments.values()):,} segments, {Path(args.output).stat().st_size:,} bytes, "
          f"{time.perf_counter() - t0:.1f} s")
    return 0


def cmd_rhythm(args) -> int:
    if args.action == "info":
        for path in args.inputs:
            db = rhythmdb.RhythmDB.load(path)
            print(f"{path}: {db.count} whole-body primitives of {len(db.names)} joints, "
                  f"{Path(path).stat().st_size:,} bytes, {db.fps:g} Hz, mean length {db.lengths.mean():.1f} frames, "
                  f"S_M {db.max_segment}, seed {db.seed}, mean distance to a primitive {db.error:.3f}, "
                  f"fingerprint {db.fingerprint:08x}, trained on {', '.join(db.trained_on) or '?'}")
        return 0
    if not args.output:
        raise CodecError("rhythm train needs -o FILE")
    clips = _training_clips(args)
    t0 = time.perf_counter()
    db = rhythmdb.train(clips, count=args.count, max_segment=args.max_segment, seed=args.seed,
                        names=[Path(p).name for p in args.inputs])
    db.save(args.output)
    print(f"wrote {args.output}: {db.count} whole-body primitives, {Path(args.output).stat().st_size:,} bytes, "
          f"{time.perf_counter() - t0:.1f} s")
    return 0


def cmd_tables(args) -> int:
    if args.action == "info":
        for path in args.inputs:
            t = motiontables.Tables.load(path)
            print(f"{path}: {len(t.groups)} groups, {t.describe()}, gestures of {t.norm} frames, spacing "
                  f"{t.spacing_cm:g} cm, discard {t.discard_deg:g} deg, b {t.interior:g}, "
                  f"{Path(path).stat().st_size:,} bytes, fingerprint {t.fingerprint:08x}, "
                  f"trained on {', '.join(t.trained_on) or '?'}")
        return 0
    if not args.output:
        raise CodecError("tables train needs -o FILE")
    clips = _training_clips(args)
    t0 = time.perf_counter()
    params = segmentation.GestureParams(args.beta, args.window, args.min_length, args.max_length)
    tables = motiontables.train(clips, args.spacing, args.discard, args.norm, args.interior, params,
                                names=[Path(p).name for p in args.inputs])
    tables.save(args.output)
    print(f"wrote {args.output}: {tables.describe()}, {Path(args.output).stat().st_size:,} bytes, "
          f"{time.perf_counter() - t0:.1f} s")
    return 0


def cmd_eval(args) -> int:
    inputs = args.inputs
    for k, path in enumerate(inputs, 1):
        motion = load(path, asf=args.asf, fps=args.fps)
        _progress(k, len(inputs), Path(path).name)
        print(f"{'file':<24}{path}")
        print(evaluate(motion, args))
        if k < len(inputs):
            print()
    return 0


def cmd_codecs(args) -> int:
    for cid in codec_ids():
        cls = codec_class(cid)
        flags = ", ".join(f for f, on in (("lossless", cls.lossless), ("streaming", cls.streaming),
                                               ("baseline for comparison", cls.baseline)) if on)
        knobs = " ".join(k.describe() for k in cls.knobs) or "-"
        quality = f"; quality knob {cls.quality.name}" if cls.quality else ""
        print(f"{cid:<12}{cls.description}")
        delay = "variable (per frame: codec.delays(motion))" if cls.variable_delay else f"{cls().delay_frames} frames"
        print(f"{'':<12}knobs: {knobs}{quality}; delay {delay}{'; ' + flags if flags else ''}")
    return 0


def add_commands(sub, common) -> None:
    p = sub.add_parser("encode", help="code motion files into .moc files",
                       description="Code each input into a .moc container. Codec knobs are options named "
                                   "after them (--name value); a target (--ratio, --bitrate, --psnr, "
                                   "--mean-error-cm, --max-error-cm) makes rate control choose the knob.")
    p.add_argument("inputs", nargs="+", metavar="IN", help=".bvh or .amc file(s)")
    p.add_argument("-o", "--output", required=True, help="output .moc file, or a directory for several inputs")
    p.add_argument("--chunk-frames", type=int, default=moc.CHUNK_FRAMES,
                   help=f"frames per independently decodable chunk (default {moc.CHUNK_FRAMES})")
    p.add_argument("--skeleton-ref", action="store_true",
                   help="store only the skeleton's id (1-2 KB smaller); decoding then needs --skeleton")
    p.add_argument("--exact-skeleton", action="store_true",
                   help="keep the skeleton's offsets bit for bit (a lossy codec's file rounds them to "
                        f"{moc.SKELETON_PRECISION_CM:g} cm, which saves 130-360 bytes on CMU skeletons)")
    add_codec_options(p)
    common(p)
    p.set_defaults(func=cmd_encode, takes_knobs=True)

    p = sub.add_parser("decode", help="decode a .moc file to BVH or ASF/AMC",
                       description="Decode a .moc file (only the chunks --frames needs) and write it.")
    p.add_argument("input", metavar="IN", help=".moc file")
    p.add_argument("-o", "--output", required=True, help=".bvh or .amc file to write")
    p.add_argument("--frames", help="FIRST:STOP, a frame range (e.g. 120:240)")
    p.add_argument("--skeleton", help="the skeleton (.asf, .bvh or .amc) of a file encoded with --skeleton-ref")
    p.add_argument("--out-asf", help="where to write the ASF when the output is .amc")
    p.add_argument("--codebook", help="the VQ codebook file (svq, tvq) the file was coded with; a file never "
                                      "names what is opened, the payload's fingerprint is checked against it")
    p.add_argument("--db", help="the primitive or rhythm database (primitives, rhythmic) the file was coded with")
    p.add_argument("--tables", help="the motion tables (posture, gesture) the file was coded with")
    p.add_argument("--max-values", type=int, default=limits.MAX_DECODED_VALUES,
                   help=f"refuse to decode more than this many values, frames x channels (default "
                        f"{limits.MAX_DECODED_VALUES:,}: a damaged file cannot exhaust memory)")
    p.set_defaults(func=cmd_decode)

    p = sub.add_parser("codebook", help="train VQ codebooks for svq and tvq (000 7.9)",
                       description="Train LBG codebooks of every size from 16 to --max-size on the clips "
                                   "(resampled to --rate) and write them to one file that encoder and "
                                   "decoder share (--codebook FILE).")
    p.add_argument("action", choices=("train", "info"), help="train: make a codebook; info: describe one")
    p.add_argument("inputs", nargs="+", metavar="IN", help="train: .bvh or .amc clips; info: the codebook file")
    p.add_argument("-o", "--output", help="codebook file to write (train)")
    p.add_argument("--kind", choices=vqbook.KINDS, default="temporal", help="temporal (tvq) or spatial (svq)")
    p.add_argument("--max-size", type=int, default=512, help="largest codebook (power of two, default 512)")
    p.add_argument("--length", type=int, default=6, help="samples per temporal vector (default 6)")
    p.add_argument("--plain", action="store_true", help="quantise the vectors themselves, not their change "
                                                        "(the codec's --predictive false)")
    p.add_argument("--rate", type=float, default=30.0, help="resample clips to this frame rate (default 30 Hz)")
    common(p)
    p.set_defaults(func=cmd_codebook)

    p = sub.add_parser("primitives", help="train primitive databases for the primitives codec (001 5.3.3)",
                       description="Cluster the quaternion segments of every joint of the clips into primitives "
                                   "(k-means++, K from 5 until the clustering error is below --threshold or K "
                                   "reaches --max-clusters) and write the database encoder and decoder share "
                                   "(--db FILE). Joints go by name; clips must share a frame rate.")
    p.add_argument("action", choices=("train", "info"), help="train: make a database; info: describe one")
    p.add_argument("inputs", nargs="+", metavar="IN", help="train: .bvh or .amc clips; info: the database file")
    p.add_argument("-o", "--output", help="database file to write (train), e.g. db.mocdb")
    p.add_argument("--max-segment", type=int, default=32, help="S_M used to cut the training clips (default 32)")
    p.add_argument("--threshold", type=float, default=primdb.ERROR_THRESHOLD,
                   help=f"clustering error (rad) that stops K growing (default {primdb.ERROR_THRESHOLD})")
    p.add_argument("--max-clusters", type=int, default=primdb.MAX_CLUSTERS,
                   help=f"largest K per joint (default {primdb.MAX_CLUSTERS})")
    p.add_argument("--seed", type=int, default=0, help="seed of the k-means++ draws (default 0)")
    common(p)
    p.set_defaults(func=cmd_primitives)

    p = sub.add_parser("rhythm", help="train whole-body primitive databases for the rhythmic codec (001 ch. 4)",
                       description="Cut the clips at whole-body key poses, choose --count of the segments as "
                                   "k-medoids and write the database encoder and decoder share (--db FILE). "
                                   "Clips must share a skeleton and a frame rate.")
    p.add_argument("action", choices=("train", "info"), help="train: make a database; info: describe one")
    p.add_argument("inputs", nargs="+", metavar="IN", help="train: .bvh or .amc clips; info: the database file")
    p.add_argument("-o", "--output", help="database file to write (train), e.g. dance.mocrd")
    p.add_argument("--count", type=int, default=rhythmdb.COUNT, help=f"primitives (default {rhythmdb.COUNT})")
    p.add_argument("--max-segment", type=int, default=32, help="longest segment in frames (default 32)")
    p.add_argument("--seed", type=int, default=0, help="seed of the k-means++ draws (default 0)")
    common(p)
    p.set_defaults(func=cmd_rhythm)

    g = segmentation.GestureParams()
    p = sub.add_parser("tables", help="train posture and gesture tables for the posture and gesture codecs (000 8.4)",
                       description="Build each body-part group's posture table (postures at least --spacing cm "
                                   "apart, greedy search) and gesture table (gesture segments stretched to --norm "
                                   "frames, those within --discard degrees of one kept dropped) from the clips, "
                                   "and write the file encoder and decoder share (--tables FILE). Clips must "
                                   "share a channel layout.")
    p.add_argument("action", choices=("train", "info"), help="train: make tables; info: describe a tables file")
    p.add_argument("inputs", nargs="+", metavar="IN", help="train: .bvh or .amc clips; info: the tables file")
    p.add_argument("-o", "--output", help="tables file to write (train), e.g. dance.moctb")
    p.add_argument("--spacing", type=float, default=motiontables.SPACING_CM,
                   help=f"posture spacing d, cm (default {motiontables.SPACING_CM:g})")
    p.add_argument("--discard", type=float, default=motiontables.DISCARD_DEG,
                   help=f"gesture discard distance D, degrees (default {motiontables.DISCARD_DEG:g})")
    p.add_argument("--norm", type=int, default=motiontables.NORM,
                   help=f"frames of a normalised gesture (default {motiontables.NORM})")
    p.add_argument("--interior", type=float, default=motiontables.INTERIOR_WEIGHT,
                   help=f"weight b of a gesture's middle in (8-13) (default {motiontables.INTERIOR_WEIGHT:g})")
    p.add_argument("--beta", type=float, default=g.beta, help=f"gesture threshold scale (default {g.beta:g})")
    p.add_argument("--window", type=float, default=g.window, help="threshold low-pass, seconds (default 0.667)")
    p.add_argument("--min-length", type=float, default=g.min_length, help="shortest gesture, s (default 0.167)")
    p.add_argument("--max-length", type=float, default=g.max_length, help=f"longest gesture, s (default "
                                                                           f"{g.max_length:g})")
    common(p)
    p.set_defaults(func=cmd_tables)

    p = sub.add_parser("eval", help="encode and decode in memory and report ratio, rate, error and speed",
                       description="Ratio vs 32-bit floats, bits per second, PSNR, VPSNR, mean/max joint "
                                   "error (cm), encode and decode time per frame.")
    p.add_argument("inputs", nargs="+", metavar="IN", help=".bvh or .amc file(s)")
    add_codec_options(p)
    common(p)
    p.set_defaults(func=cmd_eval, takes_knobs=True)

    p = sub.add_parser("truncate", help="cut an embedded (spiht) .moc file to a lower rate without re-encoding",
                       description="Every channel stream of an embedded file is cut to the prefix a smaller "
                                   "budget allows; the result decodes to a coarser motion.")
    p.add_argument("input", metavar="IN", help=".moc file coded by an embedded codec (spiht)")
    p.add_argument("-o", "--output", required=True, help=".moc file to write")
    target = p.add_mutually_exclusive_group(required=True)
    target.add_argument("--ratio", type=float, help="compression ratio vs 32-bit floats")
    target.add_argument("--bitrate", type=float, help="bits per second")
    p.add_argument("--skeleton", help="the skeleton (.asf, .bvh or .amc) of a file encoded with --skeleton-ref")
    p.set_defaults(func=cmd_truncate)

    p = sub.add_parser("codecs", help="list the codecs with their knobs and delay")
    p.set_defaults(func=cmd_codecs)

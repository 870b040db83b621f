"""``mocodec model train KIND`` and ``mocodec model info``: the trained models that encoder and
decoder share (VQ codebooks, primitive and rhythm databases, posture and gesture tables), one
command for every kind."""

from __future__ import annotations

import sys
import time
from pathlib import Path

from mocodec.cli.options import add_input_options, load_input
from mocodec.errors import CodecError

# kind -> (the file's magic, what the model is for)
KINDS = {
    "codebook": (b"MOCVQ", "LBG codebooks of every size for svq and tvq (--codebook FILE)"),
    "primitives": (b"MOCPD", "per-joint primitive databases for the primitives codec (--db FILE)"),
    "rhythm": (b"MOCRD", "whole-body primitive databases for the rhythmic codec (--db FILE)"),
    "tables": (b"MOCTB", "posture and gesture tables for the posture and gesture codecs (--tables FILE)"),
}


def _training_clips(args) -> list:
    """The clips a train command names, loaded with progress."""

    clips = []
    for k, path in enumerate(args.inputs, 1):
        if len(args.inputs) > 1:
            print(f"[{k}/{len(args.inputs)}] {Path(path).name}", file=sys.stderr, flush=True)
        clips.append(load_input(path, args))
    return clips


def _names(args) -> list[str]:
    return [Path(p).name for p in args.inputs]


def _train_codebook(args):
    from mocodec.codecs.shared import vqbook

    if args.max_size < 16 or args.max_size & (args.max_size - 1):
        raise CodecError(f"--max-size must be a power of two >= 16, got {args.max_size}")
    clips = [clip.resample(args.rate) for clip in _training_clips(args)]
    sizes = [1 << k for k in range(4, args.max_size.bit_length())]
    return vqbook.train(args.vectors, clips, sizes, predictive=not args.plain, length=args.length, names=_names(args))


def _train_primitives(args):
    from mocodec.codecs.motionprimitives import primdb

    return primdb.train(
        _training_clips(args),
        max_segment=args.max_segment,
        seed=args.seed,
        threshold=args.threshold,
        max_clusters=args.max_clusters,
        names=_names(args),
    )


def _train_rhythm(args):
    from mocodec.codecs.motionprimitives import rhythmdb

    return rhythmdb.train(
        _training_clips(args), count=args.count, max_segment=args.max_segment, seed=args.seed, names=_names(args)
    )


def _train_tables(args):
    from mocodec.codecs.model import motiontables, segmentation

    params = segmentation.GestureParams(args.beta, args.window, args.min_length, args.max_length)
    return motiontables.train(
        _training_clips(args), args.spacing, args.discard, args.norm, args.interior, params, names=_names(args)
    )


TRAIN = {"codebook": _train_codebook, "primitives": _train_primitives, "rhythm": _train_rhythm, "tables": _train_tables}


def describe(path: str) -> str:
    """One line on a model file of any kind (told by its magic)."""
    try:
        with open(path, "rb") as f:
            magic = f.read(5)
    except OSError as e:
        raise CodecError(f"model {path}: {e.strerror}") from None
    kind = next((k for k, (m, _) in KINDS.items() if m == magic), None)
    size = f"{Path(path).stat().st_size:,} bytes"
    if kind == "codebook":
        from mocodec.codecs.shared import vqbook

        book = vqbook.Codebook.load(path)
        return (
            f"{path}: {book.kind} codebook, {'predictive' if book.predictive else 'plain'}, length "
            f"{book.length}, {book.fps:g} Hz, sizes {sorted(book.books)}, groups "
            f"{', '.join(n for n, _ in book.groups)}, {size}, trained on {len(book.trained_on)} clips"
        )
    if kind == "primitives":
        from mocodec.codecs.motionprimitives import primdb

        db = primdb.PrimitiveDB.load(path)
        worst = max(db.errors.values(), default=0.0)
        return (
            f"{path}: {db.count} primitives for {len(db.primitives)} joints, {size}, {db.fps:g} Hz, "
            f"S_M {db.max_segment}, seed {db.seed}, largest clustering error {worst:.3f} rad, fingerprint "
            f"{db.fingerprint:08x}, trained on {', '.join(db.trained_on) or '?'}"
        )
    if kind == "rhythm":
        from mocodec.codecs.motionprimitives import rhythmdb

        rd = rhythmdb.RhythmDB.load(path)
        return (
            f"{path}: {rd.count} whole-body primitives of {len(rd.names)} joints, {size}, {rd.fps:g} Hz, "
            f"mean length {rd.lengths.mean():.1f} frames, S_M {rd.max_segment}, seed {rd.seed}, mean "
            f"distance to a primitive {rd.error:.3f}, fingerprint {rd.fingerprint:08x}, trained on "
            f"{', '.join(rd.trained_on) or '?'}"
        )
    if kind == "tables":
        from mocodec.codecs.model import motiontables

        t = motiontables.Tables.load(path)
        return (
            f"{path}: {len(t.groups)} groups, {t.describe()}, gestures of {t.norm} frames, spacing "
            f"{t.spacing_cm:g} cm, discard {t.discard_deg:g} deg, b {t.interior:g}, {size}, fingerprint "
            f"{t.fingerprint:08x}, trained on {', '.join(t.trained_on) or '?'}"
        )
    magics = ", ".join(repr(m) for m, _ in KINDS.values())
    raise CodecError(f"model {path}: not a mocodec model (expected one of {magics} at byte 0)")


def cmd_train(args) -> int:
    t0 = time.perf_counter()
    model = TRAIN[args.kind](args)
    model.save(args.output)
    print(
        f"{describe(args.output)} ({time.perf_counter() - t0:.1f} s)".replace(
            f"{args.output}: ", f"wrote {args.output}: ", 1
        )
    )
    return 0


def cmd_info(args) -> int:
    for path in args.inputs:
        print(describe(path))
    return 0


def _kind_options(kind: str, p) -> None:
    """The training options of one kind of model. The defaults are the training modules' own
    (checked by a test), written out so that ``--help`` needs no import."""
    if kind == "codebook":
        p.add_argument(
            "--vectors",
            choices=("temporal", "spatial"),
            default="temporal",
            help="temporal (for tvq) or spatial (for svq) vectors",
        )
        p.add_argument("--max-size", type=int, default=512, help="largest codebook (power of two, default 512)")
        p.add_argument("--length", type=int, default=6, help="samples per temporal vector (default 6)")
        p.add_argument(
            "--plain",
            action="store_true",
            help="quantise the vectors themselves, not their change (the codec's --predictive false)",
        )
        p.add_argument("--rate", type=float, default=30.0, help="resample clips to this frame rate (default 30 Hz)")
    elif kind == "primitives":
        p.add_argument("--max-segment", type=int, default=32, help="S_M used to cut the training clips (default 32)")
        p.add_argument(
            "--threshold", type=float, default=0.01, help="clustering error (rad) that stops K growing (default 0.01)"
        )
        p.add_argument("--max-clusters", type=int, default=25, help="largest K per joint (default 25)")
        p.add_argument("--seed", type=int, default=0, help="seed of the k-means++ draws (default 0)")
    elif kind == "rhythm":
        p.add_argument("--count", type=int, default=20, help="primitives (default 20)")
        p.add_argument("--max-segment", type=int, default=32, help="longest segment in frames (default 32)")
        p.add_argument("--seed", type=int, default=0, help="seed of the k-means++ draws (default 0)")
    else:
        p.add_argument("--spacing", type=float, default=5.0, help="posture spacing d, cm (default 5)")
        p.add_argument("--discard", type=float, default=5.0, help="gesture discard distance D, degrees (default 5)")
        p.add_argument("--norm", type=int, default=30, help="frames of a normalised gesture (default 30)")
        p.add_argument(
            "--interior",
            type=float,
            default=0.5,
            help="weight b of a gesture's middle in the similarity of gestures (default 0.5)",
        )
        p.add_argument("--beta", type=float, default=0.75, help="gesture threshold scale (default 0.75)")
        p.add_argument("--window", type=float, default=20 / 30, help="threshold low-pass, seconds (default 0.667)")
        p.add_argument("--min-length", type=float, default=5 / 30, help="shortest gesture, s (default 0.167)")
        p.add_argument("--max-length", type=float, default=2.0, help="longest gesture, s (default 2)")


def add_commands(sub) -> None:
    p = sub.add_parser(
        "model",
        description="Trained models that encoder and decoder share: "
        + "; ".join(f"{k}: {text}" for k, (_, text) in KINDS.items())
        + ".",
    )
    actions = p.add_subparsers(dest="action", required=True, metavar="ACTION")
    train = actions.add_parser(
        "train",
        help="train a model on clips",
        description="Train a model on .bvh or .amc clips and write it (-o FILE).",
    )
    kinds = train.add_subparsers(dest="kind", required=True, metavar="KIND")
    for kind, (_, text) in KINDS.items():
        k = kinds.add_parser(kind, help=text, description=f"Train {text}.")
        k.add_argument("inputs", nargs="+", metavar="IN", help="motion clips: .bvh, .amc, .gltf, .glb or .fbx")
        k.add_argument("-o", "--output", required=True, help="model file to write")
        _kind_options(kind, k)
        add_input_options(k)
        k.set_defaults(func=cmd_train)
    info = actions.add_parser("info", help="describe model files of any kind")
    info.add_argument("inputs", nargs="+", metavar="FILE", help="model file(s)")
    info.set_defaults(func=cmd_info)

"""The library-scale commands of the CLI: ``bench`` (rate-distortion and speed of every codec
and baseline, with a report) and ``compress-dir`` (a whole folder of clips into .moc files),
both on the local cores or a Dask cluster."""

from __future__ import annotations

import sys

from mocodec.bench import points, suite
from mocodec.bench.compressdir import compress_dir
from mocodec.cli.options import add_codec_options, target_of
from mocodec.codecs import codec_class


def _where(p) -> None:
    p.add_argument("--jobs", type=int, help="worker processes (default: every core)")
    p.add_argument(
        "--scheduler",
        metavar="tcp://HOST:PORT",
        help="run on this Dask scheduler's workers (clip paths must be readable there)",
    )
    p.add_argument("--dask", action="store_true", help="run on a local Dask cluster of --jobs workers")
    p.add_argument("--quiet", action="store_true", help="no progress bar")


def _bar(args) -> bool:
    return not args.quiet and sys.stderr.isatty()


def cmd_bench(args) -> int:
    codecs = args.codecs or suite.default_codecs()
    for c in codecs:
        codec_class(c)  # unknown ids fail before any work
    result = suite.run(
        args.data,
        args.out,
        codecs,
        args.points,
        args.errors,
        args.ratios,
        args.bitrates,
        args.jobs,
        args.scheduler,
        args.dask,
        progress=_bar(args),
        report=not args.no_report,
        command="mocodec " + " ".join(sys.argv[1:]),
        knobs=args.knobs,
    )
    m = result.meta
    print(
        f"{args.out}: {len(result.rows)} rows from {m['clips']} clips x {len(m['codecs'])} codecs; "
        f"{m['tasks_run']} tasks run, {m['tasks_resumed']} resumed, wall time {m['wall_s']:.0f} s"
    )
    if not args.no_report:
        print(f"report: {args.out}/report.html (and report.md); table: {args.out}/results.csv")
    for r in result.failures:
        print(f"failed: {r['clip']} {r['codec']} {r['point']}: {r['message']}", file=sys.stderr)
    return 1 if result.failures else 0


def cmd_compress_dir(args) -> int:
    out = compress_dir(
        args.input,
        args.output,
        args.codec,
        args.knobs,
        target_of(args),
        args.jobs,
        args.scheduler,
        args.dask,
        progress=_bar(args),
    )
    raw = sum(r["raw_bytes"] for r in out.written)
    coded = sum(r["bytes"] for r in out.written)
    ratio = f", ratio {raw / coded:.1f} vs 32-bit floats" if coded else ""
    print(
        f"{args.output}: {len(out.written)} clips written ({coded:,} bytes{ratio}), {len(out.skipped)} already "
        f"there, {len(out.failed)} failed, {out.wall_s:.1f} s"
    )
    for source, message in out.failed:
        print(f"failed: {source}: {message}", file=sys.stderr)
    return 1 if out.failed else 0


def add_commands(sub) -> None:
    p = sub.add_parser(
        "bench",
        description="For every clip and codec: a sweep of the codec's quality knob and/or "
        "rate-controlled targets, each measured (size, ratio, bit rate, PSNR, VPSNR, "
        "joint, shell and foot errors, speed). Writes results.csv, meta.json, "
        "rows.jsonl (resumes a stopped run) and report.html / report.md. Codec knobs as --name "
        "value apply to the codecs that have them (e.g. --effort 1 for kinwave).",
    )
    p.add_argument("data", nargs="+", metavar="DATA", help=".bvh/.amc files or folders (searched recursively)")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder")
    p.add_argument("--codecs", nargs="+", metavar="ID", help="codecs to run (default: all but raw)")
    p.add_argument(
        "--points",
        nargs="+",
        choices=points.KINDS,
        default=list(points.DEFAULT_KINDS),
        help="knob: a sweep of the quality knob; error/ratio/bitrate: rate-controlled targets "
        f"(default: {' '.join(points.DEFAULT_KINDS)})",
    )
    p.add_argument(
        "--errors",
        nargs="+",
        type=float,
        default=list(points.DEFAULT_ERRORS_CM),
        metavar="CM",
        help=f"max joint error targets (default {' '.join(map(str, points.DEFAULT_ERRORS_CM))})",
    )
    p.add_argument(
        "--ratios",
        nargs="+",
        type=float,
        default=list(points.DEFAULT_RATIOS),
        metavar="R",
        help="compression ratio targets (default 10 20 40 60 80 100)",
    )
    p.add_argument(
        "--bitrates",
        nargs="+",
        type=float,
        default=list(points.DEFAULT_BITRATES),
        metavar="BPS",
        help="bit rate targets in bit/s",
    )
    p.add_argument("--no-report", action="store_true", help="only the tables, no plots or report")
    _where(p)
    p.set_defaults(func=cmd_bench, takes_knobs=True)

    p = sub.add_parser(
        "compress-dir",
        description="Every .bvh/.amc under IN_DIR becomes a .moc file at the same relative path "
        "under OUT_DIR. Files already there are skipped (rerun to resume); a clip "
        "that fails is reported and the others go on. Codec knobs as --name value.",
    )
    p.add_argument("input", metavar="IN_DIR")
    p.add_argument("output", metavar="OUT_DIR")
    add_codec_options(p)
    _where(p)
    p.set_defaults(func=cmd_compress_dir, takes_knobs=True)

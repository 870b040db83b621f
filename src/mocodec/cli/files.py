"""The commands on motion files: ``info``, ``convert``, ``compare``, ``analyze`` and ``demo``."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from mocodec.cli.options import add_codec_options, add_input_options, load_input, rate_text, skeleton_from
from mocodec.codecs import checked_config
from mocodec.data import SAMPLE_CLIP
from mocodec.formats import load, save, with_units
from mocodec.formats.gltfwrite import MESHES
from mocodec.motion import Motion


def _human_bytes(n: float) -> str:
    for unit in ("B", "KB", "MB", "GB"):
        if n < 1024 or unit == "GB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1024
    return f"{n} B"  # pragma: no cover


def describe(motion: Motion, path: str) -> str:
    """The ``info`` summary of a motion."""
    sk = motion.skeleton
    parts: dict[str, int] = {}
    for i, part in enumerate(sk.body_parts):
        parts[part] = parts.get(part, 0) + len(sk.joints[i].channels)
    root = motion.root_positions() / sk.units_per_metre
    height = float(np.ptp(sk.rest_positions[:, 1])) / sk.units_per_metre
    span = sk.span() / sk.units_per_metre
    lines = [
        f"file        {path}",
        f"skeleton    {len(sk)} joints ({int(sk.end_sites.sum())} end sites), {sk.num_channels} channels "
        f"({int(sk.rotation_mask.sum())} rotation, {int((~sk.rotation_mask).sum())} translation)",
        f"units       {sk.units_per_metre:.6g} per metre; rest-pose height {height:.2f} m, span {span:.2f} m",
        f"frames      {motion.num_frames} at {motion.fps:g} fps, spanning {motion.time_span:.3f} s",
        f"raw size    {_human_bytes(motion.raw_bits / 8)} at 32-bit floats, {motion.raw_bitrate / 1000:.1f} kbit/s",
        f"root path   {np.linalg.norm(np.diff(root[:, [0, 2]], axis=0), axis=1).sum():.2f} m horizontal",
        "body parts  " + ", ".join(f"{p} {n}" for p, n in parts.items() if n),
    ]
    if "dropped_m" in sk.metadata:
        lines.insert(
            4,
            f"precision   {sk.metadata['precision_m'] * 100:.1e} cm (float32): motion within it is taken as "
            f"still, which moves joints by at most {sk.metadata['dropped_m'] * 100:.1e} cm",
        )
    return "\n".join(lines)


def describe_moc(path: str, skeleton_path: str | None = None) -> str:
    """The ``info`` summary of a .moc file, from its header and index (nothing is decoded);
    ``skeleton_path`` gives the skeleton of a file coded without one."""
    from mocodec import moc

    c = moc.info(path, skeleton_from(skeleton_path))
    sk, codec = c.skeleton, c.header["codec"]
    knobs = ", ".join(f"{k}={str(v)[:40]}" for k, v in checked_config(codec, f"{path}: header").items())
    seconds = c.frames / c.fps
    raw_bytes = c.frames * sk.num_channels * 4
    lines = [
        f"file        {path}",
        f"codec       {codec['codec']}" + (f" ({knobs})" if knobs else ""),
        f"skeleton    {len(sk)} joints, {sk.num_channels} channels",
        f"frames      {c.frames} at {c.fps:g} fps = {seconds:.2f} s, in {len(c.index)} chunks",
        f"size        {_human_bytes(c.size)}: ratio {raw_bytes / max(c.size, 1):.2f} vs 32-bit floats, "
        f"{rate_text(c.size, seconds)}",
    ]
    return "\n".join(lines)


def cmd_info(args) -> int:
    for path in args.files:
        if str(path).lower().endswith(".moc"):
            print(describe_moc(path, args.skeleton))
            if len(args.files) > 1:
                print()
            continue
        motion = load_input(path, args)
        print(describe(motion, path))
        if args.joints:
            sk = motion.skeleton
            print(f"{'joint':<22}{'parent':<18}{'part':<12}{'depth':>5}{'bone m':>9}  channels")
            for i, j in enumerate(sk.joints):
                parent = sk.names[j.parent] if j.parent >= 0 else "-"
                print(
                    f"{j.name:<22}{parent:<18}{sk.body_parts[i]:<12}{sk.chain_depths[i]:>5}"
                    f"{sk.bone_lengths[i] / sk.units_per_metre:>9.3f}  {' '.join(j.channels)}"
                )
        if len(args.files) > 1:
            print()
    return 0


def cmd_convert(args) -> int:
    """Convert, then read the written file back: motion other than what was read is an error,
    and the file does not stay (formats/verify.py)."""
    from mocodec.errors import ConversionError
    from mocodec.formats import verify

    motion = load_input(args.input, args)
    written = save(motion, args.output, asf=args.out_asf, mesh=args.mesh)
    asf = next((p for p in written if p.suffix.lower() == ".asf"), None)
    back = load(args.output, asf=asf, fps=motion.fps if asf else None)
    error, tolerance = verify.joint_error_m(motion, back), verify.tolerance_m(motion)
    if not error <= tolerance:
        for path in written:
            path.unlink(missing_ok=True)
        raise ConversionError(
            f"{args.output}: the written motion reads back {error * 100:.2g} cm from what {args.input} holds "
            f"(more than {tolerance * 100:.2g} cm): not written; please report it"
        )
    print(
        f"wrote {', '.join(str(p) for p in written)} ({motion.num_frames} frames, joints within {error * 100:.1e} cm)"
    )
    return 0


def cmd_compare(args) -> int:
    import json

    from mocodec.metrics import compare

    original = load_input(args.original, args)
    if Path(args.decoded).suffix.lower() == ".moc":  # a coded file, decoded here
        from mocodec import moc

        decoded = moc.decode(args.decoded, skeleton=original.skeleton)
    else:
        asf = args.decoded_asf or args.asf
        decoded = load(args.decoded, asf=asf, fps=args.fps, animation=args.animation, units_per_metre=args.units)
    if decoded.skeleton.units_per_metre != original.skeleton.units_per_metre:  # e.g. a BVH written in cm
        decoded = with_units(decoded, original.skeleton.units_per_metre)
    result = compare(original, decoded, shell_cm=args.shell_cm)
    if args.json:
        print(json.dumps(result.as_dict(per_joint=args.per_joint), indent=2, allow_nan=False))
        return 0
    print(f"original    {args.original}\ndecoded     {args.decoded}\n")
    print(result.table())
    if args.per_joint:
        print()
        print(result.per_joint_table())
    return 0


def cmd_analyze(args) -> int:
    import json

    from mocodec.analysis import analyze, summary_text
    from mocodec.formats.fileio import atomic_write

    motion = load_input(args.file, args)
    result = analyze(motion, noise_deg=args.noise_deg, noise_cm=args.noise_cm)
    print(summary_text(result, args.file))
    if args.out:
        out = Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
        atomic_write(out / "analysis.json", json.dumps(result, indent=1, allow_nan=False) + "\n")
        written = [out / "analysis.json"]
        if not args.no_plots:
            from mocodec.analysis.plots import write_plots

            written += write_plots(motion, out)
        print(f"\nwrote {', '.join(str(p) for p in written)}")
    return 0


def _sample() -> Motion:
    return load(SAMPLE_CLIP)


def cmd_demo(args) -> int:
    """``eval`` of the default codec on the bundled sample clip."""
    from mocodec.cli.coding import evaluate

    motion = _sample()
    print(describe(motion, f"(bundled) {SAMPLE_CLIP.name}"))
    print()
    print(evaluate(motion, args))
    print("\nTry: mocodec codecs; mocodec eval FILE --codec ID; mocodec encode FILE -o out.moc")
    return 0


def cmd_warmup(args) -> int:
    """Code one second of the bundled clip with the codecs named, by default every built-in
    codec that needs no trained model or optional library and the relay's packet kernels:
    numba compiles each kernel once and caches it (beside the package, or in the user's cache
    directory when it is read-only)."""
    import multiprocessing
    import time
    from concurrent.futures import ProcessPoolExecutor

    from mocodec import moc
    from mocodec.codecs import codec_class, codec_ids, get_codec
    from mocodec.errors import CodecError
    from mocodec.stream import framing

    motion = _sample()
    clip = motion[: int(motion.fps)]
    t0 = time.perf_counter()
    warmed, skipped = [], []
    ids = [
        cid
        for cid in args.codecs or codec_ids()
        if args.codecs or not (codec_class(cid).baseline or any(k.path for k in codec_class(cid).knobs))
    ]
    parts = dict.fromkeys(part for cid in ids for part in codec_class(cid).warm_parts)
    if not args.codecs:  # everything: the relay's packet kernels too
        parts[framing.warm] = None
    # a second process compiles the codecs' shared parts (numba caches them) while this one
    # codes the clip: the kernels compile one at a time in a process, and a machine has cores
    with ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn")) as side:
        compiling = [side.submit(part) for part in parts]
        for cid in ids:
            try:
                moc.round_trip(clip, get_codec(cid))
                warmed.append(cid)
            except CodecError:
                skipped.append(cid)
        for done in compiling:
            done.result()
    motion.positions_m()
    print(
        f"compiled or loaded the kernels of {len(warmed)} codecs in {time.perf_counter() - t0:.1f} s"
        + (f" (skipped: {', '.join(skipped)})" if skipped else "")
    )
    return 0


def add_commands(sub) -> None:
    p = sub.add_parser(
        "info",
        description="Skeleton, frames, rate, duration, channels, raw size and bit rate at 32-bit floats; "
        "for a .moc file its codec, size, ratio and bit rate.",
    )
    p.add_argument("files", nargs="+", metavar="FILE", help="motion file (.bvh, .amc, .gltf, .glb, .fbx) or .moc file")
    p.add_argument("--joints", action="store_true", help="also list every joint (motion files)")
    p.add_argument("--skeleton", help="the skeleton (.asf, .bvh or .amc) of a .moc file encoded with --skeleton-ref")
    add_input_options(p)
    p.set_defaults(func=cmd_info)

    p = sub.add_parser(
        "convert",
        description="Convert a motion file; the pose of every frame is kept exactly. "
        "Writing .amc also writes its .asf (same stem unless --out-asf).",
    )
    p.add_argument("input", metavar="IN", help="motion file: .bvh, .amc, .gltf, .glb or .fbx")
    p.add_argument("output", metavar="OUT", help="motion file to write: .bvh, .amc, .gltf or .glb")
    p.add_argument("--out-asf", help="where to write the ASF when OUT is .amc")
    p.add_argument(
        "--mesh",
        choices=MESHES,
        help="with OUT .gltf or .glb: also write a skinned body made from the skeleton, so the file "
        "plays as a character in glTF viewers (docs/viewer.md)",
    )
    add_input_options(p)
    p.set_defaults(func=cmd_convert)

    p = sub.add_parser(
        "compare",
        description="PSNR, NSNR, visual PSNR (VPSNR), the group measures of the body-part vectors, joint and "
        "shell position errors in cm, foot sliding, jerk, joint-limit violations "
        "and derivative outliers. Both files need the same skeleton, rate and "
        "frame count.",
    )
    p.add_argument("original", metavar="ORIGINAL", help="motion file: .bvh, .amc, .gltf, .glb or .fbx")
    p.add_argument(
        "decoded",
        metavar="DECODED",
        help="motion file (.bvh, .amc, .gltf, .glb or .fbx) or a .moc file, decoded here (one coded "
        "with --skeleton-ref takes ORIGINAL's skeleton)",
    )
    p.add_argument("--decoded-asf", help="ASF skeleton of an .amc DECODED (default: as for ORIGINAL)")
    p.add_argument("--json", action="store_true", help="print JSON instead of a table")
    p.add_argument("--per-joint", action="store_true", help="also list errors per joint (and per DOF in JSON)")
    p.add_argument("--shell-cm", type=float, default=3.0, help="shell distance off each bone (default 3 cm)")
    add_input_options(p)
    p.set_defaults(func=cmd_compare)

    p = sub.add_parser(
        "analyze",
        description="Per-DOF ranges, usable resolution in bits and the raw bit rate; per body "
        "part the spectra (Welch, Blackman-Tukey, AR) with their 99%% power "
        "frequency and 40/50 dB cut-offs, the Markov fit of the autocorrelation, "
        "a stationarity check and the shape of the first-difference PDF.",
    )
    p.add_argument("file", metavar="FILE", help="motion file: .bvh, .amc, .gltf, .glb or .fbx")
    p.add_argument("--out", metavar="DIR", help="write analysis.json and PNG plots here")
    p.add_argument("--no-plots", action="store_true", help="with --out, write only the JSON")
    p.add_argument("--noise-deg", type=float, default=0.1, help="sensor noise of angles (std, default 0.1 deg)")
    p.add_argument("--noise-cm", type=float, default=0.1, help="sensor noise of positions (std, default 0.1 cm)")
    add_input_options(p)
    p.set_defaults(func=cmd_analyze)

    p = sub.add_parser(
        "demo",
        description="Encode and decode the bundled CMU walk with the default codec and "
        "report ratio, bit rate, error and speed (the `eval` table).",
    )
    add_codec_options(p)
    p.set_defaults(func=cmd_demo, takes_knobs=True)

    p = sub.add_parser(
        "warmup",
        description="Compile and cache the numerical kernels of every codec that needs "
        "no trained model, or of the codecs named (a minute once after install for all of them; "
        "`make demo` warms the demo's codec, `make test` all), so no later command pays for it.",
    )
    p.add_argument("codecs", nargs="*", metavar="CODEC", help="the codecs to warm up (default: every one)")
    p.set_defaults(func=cmd_warmup)

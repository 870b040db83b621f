"""The capture command of the CLI: ``capture LOG -o OUT.bvh`` converts a sensor log to a motion
of the built-in human model (003 ch. 4); ``capture --simulate CLIP -o LOG.npz`` makes the
sensor log the minimal tracker configuration would record of a clip."""

from __future__ import annotations

import time

from mocodec.capture.converter import convert
from mocodec.capture.sensors import read_log, write_log
from mocodec.capture.simulate import simulate
from mocodec.cli.options import add_input_options, load_input
from mocodec.errors import MocodecError
from mocodec.formats import save


def cmd_capture(args) -> int:
    if args.simulate:
        motion = load_input(args.simulate, args)
        log = simulate(motion, args.noise_deg, args.noise_cm, args.seed)
        if not str(args.output).endswith(".npz"):
            raise MocodecError(f"{args.output}: a simulated sensor log is written as .npz")
        write_log(log, args.output)
        print(
            f"{args.output}: {log.num_frames} frames of 4 trackers and 2 gloves at {log.fps:g} Hz "
            f"(noise {args.noise_deg:g} deg, {args.noise_cm:g} cm, seed {args.seed})"
        )
        return 0
    if args.log is None:
        raise MocodecError("capture needs a sensor LOG, or --simulate CLIP")
    log = read_log(args.log)
    t0 = time.perf_counter()
    motion = convert(log, wrist_correction=not args.no_wrist_correction)
    seconds = time.perf_counter() - t0
    written = save(motion, args.output)
    print(
        f"{', '.join(map(str, written))}: {motion.num_frames} frames at {motion.fps:g} Hz on the human model, "
        f"converted at {motion.num_frames / max(seconds, 1e-9):,.0f} frames/s"
    )
    return 0


def add_commands(sub) -> None:
    p = sub.add_parser(
        "capture",
        description="Converts a sensor log of the minimal tracker configuration (trackers on "
        "the hips, the head and both wrists; two data gloves) to a motion of the built-in "
        "80-DOF human model by closed-form inverse kinematics. With --simulate, makes "
        "such a log from any clip instead. See docs/capture.md.",
    )
    p.add_argument("log", nargs="?", metavar="LOG", help="sensor log (.npz)")
    p.add_argument(
        "-o",
        "--output",
        required=True,
        help="motion file to write (.bvh, .amc, .gltf or .glb), or the log (.npz) with --simulate",
    )
    p.add_argument(
        "--no-wrist-correction",
        action="store_true",
        help="keep the joint angles as solved, not moved so the wrists land on their trackers (4-29)",
    )
    p.add_argument("--simulate", metavar="CLIP", help="make a sensor log of this clip instead")
    p.add_argument("--noise-deg", type=float, default=0.5, help="tracker orientation noise (deg, default 0.5)")
    p.add_argument("--noise-cm", type=float, default=0.3, help="tracker position noise (cm, default 0.3)")
    p.add_argument("--seed", type=int, default=0)
    add_input_options(p)
    p.set_defaults(func=cmd_capture)

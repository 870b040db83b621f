"""The viewer commands of the CLI: ``view`` (the original and the decoded motion in the
browser, or a relay room live) and ``study run`` / ``study report`` (the perceptual studies of
001, DSCQS and the 2AFC staircase)."""

from __future__ import annotations

import json
from pathlib import Path
from urllib.parse import urlencode

from mocodec.extras import require

require("aiohttp", "view", "the viewer")

from mocodec.cli.options import PORT, add_codec_options, target_of  # noqa: E402
from mocodec.errors import MocodecError  # noqa: E402
from mocodec.viewer import study  # noqa: E402
from mocodec.viewer.server import make_app, serve  # noqa: E402
from mocodec.viewer.session import ViewSession, load_reference  # noqa: E402
from mocodec.viewer.study_server import make_study_app  # noqa: E402


def cmd_view(args) -> int:
    if args.file is None and args.relay is None:
        raise MocodecError("view needs a FILE, or --relay ws://HOST:PORT to watch a room")
    session = None
    if args.file is not None:
        session = ViewSession(load_reference(args.file, args.asf), Path(args.file).name)
        session.code(args.codec, args.knobs, target_of(args))
    page = f"?{urlencode({'room': args.room, 'token': args.token or ''})}" if args.room else ""
    serve(make_app(session, args.relay), args.host, args.port, not args.no_browser, page)
    return 0


def cmd_study_run(args) -> int:
    cfg = study.load_config(args.config)
    session = study.start(cfg, args.participant)
    serve(make_study_app(session, args.out), args.host, args.port, not args.no_browser)
    return 0


def cmd_study_report(args) -> int:
    result = study.report(args.results)
    if args.json:
        print(json.dumps(result, indent=1))
        return 0
    for label, d in result["dmos"].items():
        lo, hi = d["ci95"]
        print(f"DMOS {label}: {d['mean']:.2f} (95% CI {lo:.2f}..{hi:.2f}, {d['n']} participants)")
    t = result["threshold_t_lower"]
    if t:
        lo, hi = t["ci95"]
        print(f"t_L threshold: {t['mean']:.4f} rad (95% CI {lo:.4f}..{hi:.4f}, {t['n']} participants)")
    if not result["dmos"] and not t:
        print("no finished DSCQS case or staircase in these files")
    return 0


def add_commands(sub) -> None:
    p = sub.add_parser(
        "view",
        description="Serves a page (three.js, no network needed) that plays the clip and its decoded "
        "version in sync, colours each decoded joint by its error, charts the error over "
        "time and shows ratio, bit rate, joint errors, PSNR and VPSNR; codec and knobs "
        "can be changed in the page. Opens .bvh, .amc, .gltf, .glb, .fbx and .moc (a .moc "
        "file's motion is the reference). With --relay, the page also watches a relay room live (every "
        "avatar and the bit rate it gets): the page joins the relay itself and decodes the streams "
        "in the browser (kinwave-live; streams of other codecs are listed, not drawn). Codec "
        "knobs as --name value.",
    )
    p.add_argument(
        "file", metavar="FILE", nargs="?", help=".bvh, .amc, .gltf, .glb, .fbx or .moc (optional with --relay)"
    )
    add_codec_options(p)
    p.add_argument("--port", type=PORT, default=8770, help="port (default 8770; 0: any free port)")
    p.add_argument("--host", default="127.0.0.1")
    p.add_argument("--no-browser", action="store_true", help="do not open the default browser")
    p.add_argument("--asf", help="ASF skeleton of an .amc input (default: <subject>.asf beside it)")
    p.add_argument(
        "--relay",
        metavar="ws://HOST:PORT",
        help="a relay whose rooms the page can watch (?room=R&token=T); the browser connects to it",
    )
    p.add_argument("--room", help="open the page on this room of --relay")
    p.add_argument("--token", help="the room token for --room")
    p.set_defaults(func=cmd_view, takes_knobs=True)

    p = sub.add_parser("study")
    steps = p.add_subparsers(dest="step", required=True)
    q = steps.add_parser(
        "run",
        help="run one participant's session of a study configured by a JSON file",
        description="Serves the study page; the results are saved as JSON in --out when the "
        "session ends. See docs/viewer.md for the configuration.",
    )
    q.add_argument("config", metavar="STUDY.json")
    q.add_argument("--out", required=True, metavar="DIR", help="folder for the results files")
    q.add_argument("--participant", default="anonymous", help="a name or code for the results file")
    q.add_argument("--port", type=PORT, default=8771)
    q.add_argument("--host", default="127.0.0.1")
    q.add_argument("--no-browser", action="store_true")
    q.set_defaults(func=cmd_study_run)
    q = steps.add_parser("report", help="DMOS per case and t_L thresholds, with 95%% confidence intervals")
    q.add_argument("results", nargs="+", metavar="RESULT.json")
    q.add_argument("--json", action="store_true", help="the figures as JSON")
    q.set_defaults(func=cmd_study_report)

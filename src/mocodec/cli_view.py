"""The viewer command of the CLI: ``view`` (the original and the decoded motion in the browser)."""

from __future__ import annotations

from pathlib import Path
from urllib.parse import urlencode

from mocodec.cli_coding import TARGET_OPTIONS, add_codec_options
from mocodec.errors import MocodecError
from mocodec.viewer.server import serve
from mocodec.viewer.session import ViewSession, load_reference


def cmd_view(args) -> int:
    if args.file is None and args.relay is None:
        raise MocodecError("view needs a FILE, or --relay ws://HOST:PORT to watch a room")
    session = None
    if args.file is not None:
        session = ViewSession(load_reference(args.file, args.asf), Path(args.file).name)
        target = next(((dest, getattr(args, dest)) for _, dest, _ in TARGET_OPTIONS
                       if getattr(args, dest) is not None), None)
        session.code(args.codec, args.knobs, target)
    page = f"?{urlencode({'room': args.room, 'token': args.token or ''})}" if args.room else ""
    serve(session, args.host, args.port, not args.no_browser, args.relay, page)
    return 0


def add_commands(sub) -> None:
    p = sub.add_parser("view", help="watch the original and the decoded motion side by side in the browser",
                       description="Serves a page (three.js, no network needed) that plays the clip and its decoded "
                                   "version in sync, colours each decoded joint by its error, charts the error over "
                                   "time and shows ratio, bit rate, joint errors, PSNR and VPSNR; codec and knobs "
                                   "can be changed in the page. Opens .bvh, .amc and .moc (a .moc file's motion is "
                                   "the reference). With --relay, the page also watches a relay room live (every avatar and the bit "
                                   "rate it gets). Codec knobs as --name value.")
    p.add_argument("file", metavar="FILE", nargs="?", help=".bvh, .amc or .moc (optional with --relay)")
    add_codec_options(p)
    p.add_argument("--port", type=int, default=8770, help="port (default 8770; 0: any free port)")
    p.add_argument("--host", default="127.0.0.1")
    p.add_argument("--no-browser", action="store_true", help="do not open the default browser")
    p.add_argument("--asf", help="ASF skeleton of an .amc input (default: <subject>.asf beside it)")
    p.add_argument("--relay", metavar="ws://HOST:PORT", help="a relay whose rooms the page can watch (?room=R&token=T)")
    p.add_argument("--room", help="open the page on this room of --relay")
    p.add_argument("--token", help="the room token for --room")
    p.set_defaults(func=cmd_view, takes_knobs=True)

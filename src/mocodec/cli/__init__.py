"""The ``mocodec`` command line. Each command lives in a module of this package; only the
chosen command's module is imported (``mocodec --help`` imports none), so the command line
starts quickly.

User errors (bad files, impossible conversions) print one line and exit with status 2.
"""

from __future__ import annotations

import argparse
import sys
import warnings
from importlib import import_module

from mocodec.errors import MocodecError
from mocodec.version import __version__

# command -> (its module in this package, one line of help), in the order --help lists them
COMMANDS = {
    "info": ("files", "summarise motion files"),
    "convert": ("files", "convert motion files (BVH, ASF/AMC, glTF, FBX in; BVH, ASF/AMC, glTF out)"),
    "compare": ("files", "every error measure of a decoded motion against its original"),
    "analyze": ("files", "statistics, spectra and bit-rate estimates of a motion"),
    "encode": ("coding", "code motion files into .moc files"),
    "decode": ("coding", "decode a .moc file to BVH or ASF/AMC"),
    "eval": ("coding", "encode and decode in memory and report ratio, rate, error and speed"),
    "truncate": ("coding", "cut an embedded (spiht) .moc file to a lower rate without re-encoding"),
    "codecs": ("coding", "list the codecs with their knobs and delay"),
    "model": ("models", "train or describe the models that model-based codecs share"),
    "bench": ("bench", "rate-distortion and speed of every codec and baseline, with a report"),
    "compress-dir": ("bench", "code every clip of a folder into .moc files, in parallel"),
    "serve": ("stream", "run the relay server: rooms of live avatar streams over WebSocket"),
    "token": ("stream", "issue a room token signed with the relay's secret"),
    "publish": ("stream", "play a clip into a relay room as a live stream"),
    "subscribe": ("stream", "watch a relay room and record a stream to a motion file"),
    "view": ("view", "watch the original and the decoded motion side by side in the browser"),
    "study": ("view", "perceptual studies in the browser: DSCQS and the two-alternative staircase"),
    "capture": ("capture", "sensor log (4 trackers, 2 gloves) to joint angles of the human model"),
    "warmup": ("files", "compile the numerical kernels once, so the first real command runs at full speed"),
    "demo": ("files", "run the main job on the bundled sample clip"),
}
#: numpy's floating-point warnings, which a damaged file's signalling NaN or huge value raises
#: in a cast or a sum on its way to the finiteness checks that then refuse it in one line
FLOAT_WARNINGS = r"(invalid value|overflow|divide by zero) encountered"


class _Commands:
    """The subparsers action as the command modules see it: each command gets its help line
    from :data:`COMMANDS`."""

    def __init__(self, sub):
        self.sub = sub

    def add_parser(self, name: str, **kwargs):
        return self.sub.add_parser(name, help=COMMANDS[name][1], **kwargs)


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The parser, with the arguments of ``command`` (of every command with "all"); the other
    commands are listed by name and help only."""
    parser = argparse.ArgumentParser(
        prog="mocodec",
        description=(
            "Coding of human motion capture: motion files (BVH, ASF/AMC, glTF, FBX) to .moc files, "
            "live streams through a relay, and a viewer."
        ),
    )
    parser.add_argument("--version", action="version", version=f"mocodec {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    wanted = {module for name, (module, _) in COMMANDS.items() if command in ("all", name)}
    for name, (module, text) in COMMANDS.items():
        if module in wanted:
            import_module(f"mocodec.cli.{module}").add_commands(_Commands(sub))
            wanted.discard(module)
        if name not in sub.choices:
            sub.add_parser(name, help=text)
    return parser


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    command = next((a for a in argv if not a.startswith("-")), None)
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", FLOAT_WARNINGS, RuntimeWarning)
        return _run(argv, command)


def _run(argv: list[str], command: str | None) -> int:
    try:
        from mocodec.cli.options import knobs_from

        parser = build_parser(command)  # a command's module may need an extra (MocodecError)
        args, extra = parser.parse_known_args(argv)
        if extra and not getattr(args, "takes_knobs", False):
            parser.error(f"unrecognized arguments: {' '.join(extra)}")
        args.knobs = knobs_from(extra)
        return args.func(args)
    except MocodecError as e:
        print(f"mocodec: error: {e}", file=sys.stderr)
        return 2
    except OSError as e:  # "missing.moc: No such file or directory", not "[Errno 2] ..."
        where = f"{e.filename}: " if e.filename is not None else ""
        print(f"mocodec: error: {where}{e.strerror or e}", file=sys.stderr)
        return 2
    except ValueError as e:
        print(f"mocodec: error: {e}", file=sys.stderr)
        return 2

"""The streaming commands of the CLI: ``serve`` (the relay), ``token`` (a room token),
``publish`` (a clip played as a live stream) and ``subscribe`` (record what a viewer gets)."""

from __future__ import annotations

import asyncio
import logging
import math
import os
import sys
from pathlib import Path

from mocodec.extras import require

require("aiohttp", "stream", "the relay and its clients")

from mocodec.cli.coding import configured  # noqa: E402
from mocodec.cli.options import PORT, add_codec_options, add_input_options, load_input, number_in  # noqa: E402
from mocodec.errors import MocodecError  # noqa: E402
from mocodec.formats import check_writable, save  # noqa: E402
from mocodec.stream import client, tokens  # noqa: E402
from mocodec.stream.relay import TICK_HZ, Limits  # noqa: E402
from mocodec.stream.relay.server import run  # noqa: E402

PUBLISH_CODEC = "kinwave-live"  # guaranteed error, 50 ms of coding delay, decodes in the browser
LATE_S = 1.0  # a codec that holds frames back longer than this is named when it publishes


SECRET_ENV = "MOCODEC_RELAY_SECRET"
MIN_SECRET_CHARS = 16
STREAM_ID = number_in(int, 0, 2**32 - 1)  # a packet's u32
RATE = number_in(float, 0, above=True)  # rates, durations and speeds: a positive number
MAX_WORKERS = 256
MAX_TICK_HZ = 1000.0


def secret_of(args) -> str:
    """The relay secret from ``--secret-file``, ``--secret`` (visible in ``ps``: for tests
    and one-off use) or the environment (MOCODEC_RELAY_SECRET), in that order; one under
    MIN_SECRET_CHARS gets a warning (a token seen in a URL lets anyone try short secrets offline;
    tests and local trials use short ones)."""
    if args.secret_file:
        try:
            secret = Path(args.secret_file).read_text().strip()
        except OSError as e:
            raise MocodecError(f"{args.secret_file}: cannot read the secret ({e.strerror})") from None
        if not secret:
            raise MocodecError(f"{args.secret_file}: the secret file is empty")
    else:
        secret = args.secret or os.environ.get(SECRET_ENV, "")
        if not secret:
            raise MocodecError(f"give the relay secret in a file (--secret-file), in {SECRET_ENV}, or with --secret")
    if len(secret) < MIN_SECRET_CHARS:
        print(
            f"mocodec: warning: the relay secret has {len(secret)} characters, under {MIN_SECRET_CHARS} (anyone who "
            f"sees a token can try short ones offline): python -c 'import secrets; print(secrets.token_urlsafe(32))'",
            file=sys.stderr,
            flush=True,
        )
    return secret


def add_secret_options(p) -> None:
    p.add_argument("--secret-file", metavar="FILE", help="a file holding the secret room tokens are signed with")
    p.add_argument(
        "--secret", help=f"the secret itself (visible to every user in `ps`; prefer --secret-file or {SECRET_ENV})"
    )


def cmd_serve(args) -> int:
    logging.basicConfig(
        level=logging.INFO if args.verbose else logging.WARNING, format="%(asctime)s %(name)s %(levelname)s %(message)s"
    )
    limits = Limits(
        max_message_bytes=args.max_message_bytes,
        publish_messages_per_s=args.max_messages_per_s,
        publish_bytes_per_s=args.max_bytes_per_s,
    )
    secret = secret_of(args)
    if args.workers > 1:
        from mocodec.stream.relay.workers import serve_workers

        bus = args.bus or "a NATS server of its own"
        print(
            f"mocodec relay on http://{args.host}:{args.port} (WebSocket /ws, status /status), "
            f"{args.workers} workers sharing rooms through {bus}",
            flush=True,
        )
        serve_workers(
            args.host,
            args.port,
            secret,
            args.workers,
            limits,
            args.bus,
            args.tick_hz,
            lambda: print(f"{args.workers} workers listening", flush=True),
        )
        return 0
    bus = None
    if args.bus:
        from mocodec.stream.bus import NatsBus

        bus = NatsBus(args.bus)
    line = f"mocodec relay on http://{args.host}:{args.port} (WebSocket /ws, status /status)" + (
        f", bus {args.bus}" if bus else ""
    )
    # Printed once the port takes connections: scripts and tests read this line as "ready".
    run(args.host, args.port, secret, limits, bus, args.tick_hz, listening=lambda: print(line, flush=True))
    return 0


def cmd_token(args) -> int:
    print(tokens.issue(secret_of(args), args.room, args.role, args.ttl))
    return 0


def late_notice(codec, fps: float) -> str | None:
    """A line for a publisher whose codec holds each frame back more than LATE_S (a codec
    that sends a packet per segment, such as kinwave's 1024 frames): what viewers will see."""
    if codec.variable_delay or fps <= 0:
        return None
    frames = codec.delay_frames()
    if frames / fps <= LATE_S:
        return None
    return (
        f"note: {codec.id} sends a packet every {frames} frames, so viewers see each frame up to "
        f"{frames / fps:.1f} s late ({PUBLISH_CODEC} codes with 50 ms)"
    )


def cmd_publish(args) -> int:
    motion = load_input(args.file, args)
    codec, _ = configured(args, motion)
    notice = late_notice(codec, motion.fps)
    if notice:
        print(notice, file=sys.stderr)
    stats = asyncio.run(
        client.publish_clip(
            args.url,
            args.room,
            args.token,
            motion,
            codec,
            args.speed,
            args.stream,
            args.keyframe_s,
            Path(args.file).name,
        )
    )
    rate = stats.bytes * 8 / max(motion.duration, 1e-9)
    print(
        f"published {stats.frames} frames in {stats.seconds:.1f} s to room {args.room!r}: {stats.packets} packets, "
        f"{stats.bytes:,} bytes ({rate / 1000:.2f} kbit/s), {codec!r}"
    )
    return 0


def cmd_subscribe(args) -> int:
    check_writable(args.output)  # before the recording, not after it
    camera = _camera(args.camera)

    def joined() -> None:
        print(f"watching room {args.room!r} at {args.url}", file=sys.stderr, flush=True)

    motions = asyncio.run(
        client.record(
            args.url, args.room, args.token, args.frames, args.stream, args.budget, camera, args.timeout, joined=joined
        )
    )
    if not motions:
        raise MocodecError(
            f"no stream arrived in room {args.room!r}" + (f" within {args.timeout:g} s" if args.timeout else "")
        )
    stream = args.stream if args.stream is not None else next(iter(motions))
    if stream not in motions:
        raise MocodecError(f"stream {stream} did not arrive (streams seen: {', '.join(map(str, motions))})")
    motion = motions[stream]
    written = save(motion, args.output)
    others = sorted(set(motions) - {stream})
    print(
        f"{', '.join(map(str, written))}: stream {stream}, {motion.num_frames} frames at {motion.fps:g} Hz"
        + (f" (also in the room: streams {', '.join(map(str, others))})" if others else "")
    )
    return 0


def _camera(text: str) -> tuple[float, float, float]:
    try:
        x, y, z = (float(v) for v in text.split(","))
    except ValueError:
        raise MocodecError(f"--camera must be x,y,z in metres, got {text!r}") from None
    if not all(map(math.isfinite, (x, y, z))):
        raise MocodecError(f"--camera must be finite, got {text!r}")
    return x, y, z


def add_commands(sub) -> None:
    p = sub.add_parser(
        "serve",
        description="Senders publish avatar streams into rooms, viewers subscribe; every tick each "
        "viewer gets one batch, the embedded streams cut to its bandwidth by the crowd "
        "allocation (nearer and larger avatars get more). Publish and subscribe need a token from `mocodec token`.",
    )
    p.add_argument("--port", type=PORT, default=8765)
    p.add_argument("--host", default="127.0.0.1", help="address to listen on (default 127.0.0.1; 0.0.0.0: all)")
    add_secret_options(p)
    p.add_argument("--bus", metavar="nats://HOST:4222", help="share rooms with other relays through NATS")
    p.add_argument(
        "--workers",
        type=number_in(int, 1, MAX_WORKERS),
        default=1,
        help="relay processes behind the one port, sharing rooms through NATS (--bus, or a nats-server "
        "that serve starts on a free loopback port); default 1",
    )
    p.add_argument(
        "--tick-hz",
        type=number_in(float, 0, MAX_TICK_HZ, above=True),
        default=TICK_HZ,
        help=f"batches per second to each viewer (default {TICK_HZ:g})",
    )
    p.add_argument("--max-message-bytes", type=number_in(int, 1), default=Limits.max_message_bytes)
    p.add_argument(
        "--max-messages-per-s",
        type=RATE,
        default=Limits.publish_messages_per_s,
        help="per sending connection (over it: closed)",
    )
    p.add_argument(
        "--max-bytes-per-s",
        type=RATE,
        default=Limits.publish_bytes_per_s,
        help="per sending connection (over it: closed)",
    )
    p.add_argument("--verbose", action="store_true", help="log connections and refusals")
    p.set_defaults(func=cmd_serve)

    p = sub.add_parser("token")
    add_secret_options(p)
    p.add_argument("--room", required=True)
    p.add_argument("--role", choices=tokens.ROLES, default="both", help="what it allows (default both)")
    p.add_argument("--ttl", type=RATE, default=24 * 3600.0, help="lifetime in seconds (default a day)")
    p.set_defaults(func=cmd_token)

    p = sub.add_parser(
        "publish",
        description="Streams the clip at its frame rate (--speed X: X times faster) with keyframes "
        f"every --keyframe-s seconds. Codec (default {PUBLISH_CODEC}) and knobs as for "
        "encode (--name value), or a target.",
    )
    p.add_argument("file", metavar="FILE")
    _connection(p)
    p.add_argument("--speed", type=RATE, default=1.0, help="times real time (default 1)")
    p.add_argument("--stream", type=STREAM_ID, default=0, help="stream id in the room (default 0)")
    p.add_argument("--keyframe-s", type=RATE, default=1.0, help="seconds between keyframes (default 1)")
    add_codec_options(p, PUBLISH_CODEC)
    add_input_options(p)
    p.set_defaults(func=cmd_publish, takes_knobs=True)

    p = sub.add_parser(
        "subscribe",
        description="Records what a viewer receives (decoded, lost packets concealed) until "
        "--frames frames, the stream's end, or --timeout.",
    )
    _connection(p)
    p.add_argument("-o", "--output", required=True, help="motion file to write (.bvh, .amc, .gltf or .glb)")
    p.add_argument("--frames", type=number_in(int, 1), help="stop after this many frames")
    p.add_argument("--stream", type=STREAM_ID, help="stream id to record (default: the first to arrive)")
    p.add_argument("--budget", type=number_in(float, 0), default=0.0, help="this viewer's bandwidth in bit/s (0: all)")
    p.add_argument("--camera", default="0,0,0", help="this viewer's camera x,y,z in metres (default 0,0,0)")
    p.add_argument("--timeout", type=RATE, help="give up after this many seconds")
    p.set_defaults(func=cmd_subscribe)


def _connection(p) -> None:
    p.add_argument("--url", required=True, metavar="ws://HOST:PORT")
    p.add_argument("--room", required=True)
    p.add_argument("--token", required=True)

"""The relay server, its clients and its limits, over real WebSockets on loopback."""

from __future__ import annotations

import asyncio
import contextlib
import json
import shutil
import socket
import subprocess
import sys
import threading
import time

import aiohttp
import numpy as np
import pytest

from conftest import DATA, free_port
from mocodec.cli import main
from mocodec.codecs import get_codec
from mocodec.crowd import on_ladder
from mocodec.stream import tokens
from mocodec.stream.bus import NatsBus
from mocodec.stream.client import RelayRefused, connect, publish_clip, record
from mocodec.stream.live import receive_clip, stream_clip
from mocodec.stream.packets import CUTS, Reader, pack_batch, split_batch, with_cut_table
from mocodec.stream.relay import BAD_MESSAGE, RATE_LIMIT, Limits
from mocodec.stream.relay.server import Relay, start

pytestmark = pytest.mark.network  # a relay (and NATS) on loopback sockets

SECRET = "test-secret-of-the-relay-tests"


@contextlib.asynccontextmanager
async def serving(relay: Relay | None = None):
    """A relay on a free loopback port: yields its ws:// address."""
    relay = relay or Relay(SECRET)
    runner, server = await start(relay, "127.0.0.1", 0)
    port = server.sockets[0].getsockname()[1]
    try:
        yield f"ws://127.0.0.1:{port}"
    finally:
        server.close()
        await runner.cleanup()


def token(room: str = "lobby", role: str = "both", ttl: float = 600.0) -> str:
    return tokens.issue(SECRET, room, role, ttl)


def viewers(relay: Relay, count: int = 1, room: str = "lobby", budget: float = 0.0):
    """A readiness test: ``count`` viewers have joined ``room`` (and, with ``budget``, their
    settings of that budget have arrived)."""

    def ready() -> bool:
        joined = relay.core.rooms[room].viewers if room in relay.core.rooms else []
        return sum(v.budget == budget for v in joined) >= count if budget else len(joined) >= count

    return ready


async def publish_and_record(relay, url, motion, codec, speed=8.0, **watch):
    viewer = asyncio.create_task(record(url, "lobby", token(), timeout_s=30, **watch))
    await relay.until(viewers(relay, budget=watch.get("budget", 0.0)))
    await publish_clip(url, "lobby", token(), motion, codec, speed=speed)
    return await viewer


def test_a_recorded_stream_decodes_as_offline_at_the_viewers_budget(walk_bvh):
    """spiht sent at 8 kbit/s, cut by the relay to the viewer's 3 kbit/s (rounded down to the
    relay's ladder of rates): the same motion as the clip streamed at that rate and decoded
    offline."""

    async def go():
        relay = Relay(SECRET)
        async with serving(relay) as url:
            return await publish_and_record(relay, url, walk_bvh, get_codec("spiht", bits_per_second=8000), budget=3000)

    got = asyncio.run(go())[0]
    assert 2750 < on_ladder(3000) <= 3000
    offline = receive_clip(stream_clip(walk_bvh, get_codec("spiht", bits_per_second=on_ladder(3000))))
    np.testing.assert_array_equal(got.channels, offline.channels)
    whole = receive_clip(stream_clip(walk_bvh, get_codec("spiht", bits_per_second=8000)))
    assert not np.array_equal(got.channels, whole.channels)


def test_whole_streams_pass_unchanged(walk_bvh):
    async def go():
        relay = Relay(SECRET)
        async with serving(relay) as url:
            return await publish_and_record(relay, url, walk_bvh, get_codec("dpcm"))

    got = asyncio.run(go())[0]
    np.testing.assert_array_equal(got.channels, receive_clip(stream_clip(walk_bvh, get_codec("dpcm"))).channels)


def test_late_joiner_gets_the_header_and_the_last_keyframe(walk_bvh):
    async def go():
        relay = Relay(SECRET)

        def past_the_second_keyframe():
            room = relay.core.rooms.get("lobby")
            return room is not None and 0 in room.streams and room.streams[0].next_frame > 1.3 * walk_bvh.fps

        async with serving(relay) as url:
            sender = asyncio.create_task(publish_clip(url, "lobby", token(), walk_bvh, get_codec("dpcm"), speed=1.0))
            await relay.until(past_the_second_keyframe)
            got = await record(url, "lobby", token(), timeout_s=10)
            await sender
            return got[0]

    got = asyncio.run(go())
    packets = stream_clip(walk_bvh, get_codec("dpcm"))
    clean = receive_clip(packets).channels
    starts = [p.first_frame for p in packets[1:] if p.keyframe]
    start = walk_bvh.num_frames - got.num_frames
    assert start in starts[1:]  # joined at a keyframe after the first
    np.testing.assert_array_equal(got.channels, clean[start:])


@pytest.mark.parametrize("budget", [0, 1e6])  # whole, or cut to the layers that fit (all)
def test_a_viewer_that_lost_a_packet_gets_it_again_and_stays_exact(walk_bvh, budget):
    from mocodec.stream.client import Watcher

    codec = get_codec("kinwave-live", layers=2)

    async def go():
        watcher = Watcher(hold_s=0.5)  # beyond the relay's round trip on a busy test machine
        async with serving() as url:
            async with connect(url, "lobby", token(), "subscribe") as ws:
                await ws.send_str(json.dumps({"budget": budget, "camera": [0, 1.6, 3]}))
                sender = asyncio.create_task(publish_clip(url, "lobby", token(), walk_bvh, codec, speed=2.0))
                seen, lost, asked, link = 0, None, [], Reader()
                while not (watcher.decoders and watcher.decoders[0].ended):
                    msg = await asyncio.wait_for(ws.receive(), 10)
                    if msg.type != aiohttp.WSMsgType.BINARY:
                        continue
                    raws = [bytes(r) for r in split_batch(msg.data)]
                    sequences = [link.read(r).sequence for r in raws]
                    if lost is None and seen + len(raws) > 12:  # the emulated link drops one
                        lost = sequences[12 - seen]
                        del raws[12 - seen]
                    seen += len(raws)
                    watcher.take(pack_batch(raws))
                    if asks := watcher.repairs():
                        asked += asks
                        await ws.send_str(json.dumps({"repair": asks}))
                await sender
        return watcher, asked, lost

    watcher, asked, lost = asyncio.run(go())
    assert asked[0] == [0, lost]
    assert watcher.decoders[0].stats.repaired == 1 and watcher.decoders[0].stats.concealed_frames == 0
    clean = receive_clip(stream_clip(walk_bvh, codec)).channels
    np.testing.assert_array_equal(watcher.motion(0).channels, clean)


def _near_and_far(walk, codec, budget):
    """The walk and the same walk 20 m further along x, published at once to a viewer of
    ``budget`` bit/s standing at the near one's start: what the viewer got of each."""
    far = walk.with_channels(walk.channels.copy())
    x = walk.skeleton.channel_index("hip.Xposition")
    far.channels[:, x] += 20 * walk.skeleton.units_per_metre

    async def go():
        relay = Relay(SECRET)
        async with serving(relay) as url:
            camera = tuple(walk.positions_m()[0, 0])
            viewer = asyncio.create_task(
                record(url, "lobby", token(), budget=budget, camera=camera, timeout_s=30, stream=1)
            )
            await relay.until(viewers(relay, budget=budget))
            await asyncio.gather(
                publish_clip(url, "lobby", token(), walk, codec, speed=8, stream=0),
                publish_clip(url, "lobby", token(), far, codec, speed=8, stream=1),
            )
            return await viewer

    got = asyncio.run(go())
    return far, got[0], got[1]


def test_the_nearer_avatar_gets_the_larger_share(walk_bvh):
    far, near_got, far_got = _near_and_far(walk_bvh, get_codec("spiht", bits_per_second=8000), 4000)
    near_err = np.abs(near_got.channels - walk_bvh.continuous().channels).mean()
    far_err = np.abs(far_got.channels - far.continuous().channels).mean()
    assert near_err < far_err


def _max_joint_error_cm(motion, channels):
    from mocodec.kinematics import forward_kinematics

    p0, _ = forward_kinematics(motion.skeleton, motion.continuous().channels)
    p1, _ = forward_kinematics(motion.skeleton, channels)
    return float((np.linalg.norm(p1 - p0, axis=2) * 100.0 / motion.skeleton.units_per_metre).max())


def test_the_far_avatar_of_a_layered_stream_gets_the_base_layer_only(walk_bvh):
    """kinwave-live in three layers (4, 2, 1 cm): the relay keeps all of them for the near
    avatar and the base alone for the one 20 m away, by cutting packets: the near one decodes
    as the whole stream, the far one holds the base layer's bound and no more."""
    codec = get_codec("kinwave-live", layers=3)
    far, near_got, far_got = _near_and_far(walk_bvh, codec, 20000)
    whole = receive_clip(stream_clip(walk_bvh, codec, stream=0)).channels
    near = near_got.channels  # the recording stops at the far one's end: the near one may lack its last packets
    assert len(near) > 0.9 * len(whole)
    np.testing.assert_array_equal(near, whole[: len(near)])
    assert _max_joint_error_cm(walk_bvh[: len(near)], near) <= 1.0 + 1e-9
    assert 2.0 < _max_joint_error_cm(far, far_got.channels) <= 4.0 + 1e-9


@pytest.mark.parametrize(
    "bad, why",
    [
        (tokens.issue("other-secret", "lobby"), "signature"),
        (tokens.issue(SECRET, "lobby", ttl_s=1, now=time.time() - 10), "expired"),
        (tokens.issue(SECRET, "hall"), "room"),
        (tokens.issue(SECRET, "lobby", "subscribe"), "allows"),
    ],
)
def test_bad_tokens_are_refused_with_the_reason(walk_bvh, bad, why):
    async def go():
        async with serving() as url:
            with pytest.raises(RelayRefused, match=why):
                await publish_clip(url, "lobby", bad, walk_bvh, get_codec("dpcm"))

    asyncio.run(go())


def test_a_relay_that_never_welcomes_is_refused_in_time(monkeypatch):
    """A server that takes the WebSocket but says nothing: the client gives up after WELCOME_S
    with a one-line reason instead of waiting for ever."""
    from aiohttp import web

    from mocodec.stream import client

    monkeypatch.setattr(client, "WELCOME_S", 0.2)

    async def silent(request):
        ws = web.WebSocketResponse()
        await ws.prepare(request)
        await asyncio.sleep(5)
        return ws

    async def go():
        app = web.Application()
        app.router.add_get("/ws", silent)
        runner = web.AppRunner(app, shutdown_timeout=0.1)
        await runner.setup()
        site = web.TCPSite(runner, "127.0.0.1", 0)
        await site.start()
        port = runner.addresses[0][1]
        try:
            started = time.monotonic()
            with pytest.raises(RelayRefused, match="sent no welcome within 0.2 s"):
                async with connect(f"ws://127.0.0.1:{port}", "lobby", token(), "subscribe"):
                    pass
            assert time.monotonic() - started < 3.0
        finally:
            await runner.cleanup()

    asyncio.run(go())


def test_a_malformed_message_closes_that_connection_only(walk_bvh):
    async def go():
        async with serving() as url:
            viewer = asyncio.create_task(record(url, "lobby", token(), timeout_s=30))
            async with connect(url, "lobby", token(), "publish") as rogue:
                await rogue.send_bytes(b"MP this is no packet")
                msg = await rogue.receive()
                assert msg.type == aiohttp.WSMsgType.CLOSE and rogue.close_code == BAD_MESSAGE
                assert "bad message" in msg.extra
            await publish_clip(url, "lobby", token(), walk_bvh, get_codec("dpcm"), speed=8)
            return await viewer

    assert asyncio.run(go())[0].num_frames == walk_bvh.num_frames


@pytest.mark.parametrize(
    "cuts,expected",
    [
        (lambda size: [1, size + 1], "a cut table of 2 ends in order, within its"),
        (lambda size: [5, 1], "a cut table of 2 ends in order"),
        (lambda size: [1], "a cut table of 2 ends"),
        (None, "needs a cut table"),  # the relay could not cut it
    ],
    ids=["past the end", "out of order", "one short", "none"],
)
def test_a_layered_packet_without_a_cut_table_that_fits_closes_its_sender(walk_bvh, cuts, expected):
    packets = stream_clip(walk_bvh[:120], get_codec("kinwave-live", layers=3))
    payload = packets[2].codec_payload
    cuts = None if cuts is None else cuts(len(payload))
    bad = packets[2].with_payload(
        payload if cuts is None else with_cut_table(payload, cuts),
        packets[2].flags & ~CUTS if cuts is None else packets[2].flags,
    )

    async def go():
        async with serving() as url:
            async with connect(url, "lobby", token(), "publish") as rogue:
                await rogue.send_bytes(pack_batch([p.to_bytes() for p in packets[:2]] + [bad.to_bytes()]))
                msg = await rogue.receive()
                return rogue.close_code, msg.extra

    code, reason = asyncio.run(go())
    assert code == BAD_MESSAGE and "stream 0: packet 1:" in reason and expected in reason


def test_message_size_and_rate_limits_close_the_connection(walk_bvh):
    limits = Limits(max_message_bytes=4096, publish_messages_per_s=5, burst_s=1.0)
    header = stream_clip(walk_bvh[0:10], get_codec("dpcm"))[0].to_bytes()

    async def go():
        async with serving(Relay(SECRET, limits)) as url:
            async with connect(url, "lobby", token(), "publish") as ws:
                await ws.send_bytes(bytes(10_000))
                await ws.receive()
                assert ws.close_code == aiohttp.WSCloseCode.MESSAGE_TOO_BIG
            async with connect(url, "lobby", token(), "publish") as ws:
                for _ in range(20):
                    if ws.closed:
                        break
                    await ws.send_bytes(pack_batch([header]))
                msg = await ws.receive()
                assert ws.close_code == RATE_LIMIT and "rate limit" in msg.extra
            async with connect(url, "lobby", token(), "subscribe") as ws:
                await ws.send_str("{not json")
                await ws.receive()
                assert ws.close_code == BAD_MESSAGE

    asyncio.run(go())


@pytest.fixture
def nats_server():
    binary = shutil.which("nats-server", path="/usr/sbin:/usr/bin:/usr/local/bin")
    if binary is None:
        pytest.skip("nats-server is not installed (.ci/run installs Debian's nats-server)")
    port = free_port()
    proc = subprocess.Popen([binary, "-a", "127.0.0.1", "-p", str(port)], stderr=subprocess.PIPE, text=True)
    log = []
    for line in proc.stderr:  # its log: ready once it says so
        log.append(line)
        if "Server is ready" in line:
            break
    else:  # it ended without (the port taken by another test in the meantime)
        pytest.fail(f"nats-server did not start on port {port}: {''.join(log[-3:])}")
    threading.Thread(target=proc.stderr.read, daemon=True).start()  # the rest of its log, unread
    yield f"nats://127.0.0.1:{port}"
    proc.terminate()
    proc.wait(5)


def test_a_relay_whose_nats_server_is_down_says_so(monkeypatch):
    """The NATS client retries a first connection for ever (its reconnect attempts apply to it
    too): the relay gives up after CONNECT_S with a one-line error instead of hanging."""
    from mocodec.errors import MocodecError
    from mocodec.stream import bus

    monkeypatch.setattr(bus, "CONNECT_S", 0.5)
    url = f"nats://127.0.0.1:{free_port()}"

    async def go():
        started = time.monotonic()
        with pytest.raises(MocodecError, match=f"cannot reach the NATS server at {url} within 0.5 s"):
            await NatsBus(url).start(lambda room, data: asyncio.sleep(0))
        assert time.monotonic() - started < 3.0

    asyncio.run(go())


def test_two_relays_share_a_room_over_nats(walk_bvh, nats_server):
    """A sender on relay A reaches a viewer on relay B."""

    async def go():
        relay_b = Relay(SECRET, bus=NatsBus(nats_server))
        # (it once waited for 9 minutes in the full suite: the timeout's traceback says where)
        async with (
            asyncio.timeout(120),
            serving(Relay(SECRET, bus=NatsBus(nats_server))) as a,
            serving(relay_b) as b,
        ):
            viewer = asyncio.create_task(record(b, "lobby", token(), timeout_s=30))
            await relay_b.until(viewers(relay_b))
            await publish_clip(a, "lobby", token(), walk_bvh, get_codec("dpcm"), speed=8)
            return await viewer

    got = asyncio.run(go())[0]
    np.testing.assert_array_equal(got.channels, receive_clip(stream_clip(walk_bvh, get_codec("dpcm"))).channels)


def test_cli_token_and_refusal(capsys):
    assert main(["token", "--secret", SECRET, "--room", "lobby", "--role", "subscribe"]) == 0
    issued = capsys.readouterr().out.strip()
    assert tokens.verify(SECRET, issued, "lobby", "subscribe")
    port = free_port()
    code = main(
        [
            "subscribe",
            "--url",
            f"ws://127.0.0.1:{port}",
            "--room",
            "lobby",
            "--token",
            issued,
            "-o",
            "out.bvh",
            "--timeout",
            "1",
        ]
    )
    assert code == 2 and "cannot reach the relay" in capsys.readouterr().err


def raw_viewer(url: str, tok: str) -> socket.socket:
    """A viewer that completes the WebSocket handshake and then never reads: a stalled link."""
    import base64
    import os

    host, port = url.removeprefix("ws://").split(":")
    s = socket.socket()
    s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    s.connect((host, int(port)))
    key = base64.b64encode(os.urandom(16)).decode()
    s.sendall(
        (
            f"GET /ws?room=lobby&role=subscribe&token={tok} HTTP/1.1\r\nHost: {host}\r\nUpgrade: websocket\r\n"
            f"Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n\r\n"
        ).encode()
    )
    reply = b""
    while b"\r\n\r\n" not in reply:
        reply += s.recv(1)
    assert b" 101 " in reply
    return s


def test_a_stalled_viewer_is_dropped_and_the_others_go_on(walk_bvh):
    relay = Relay(SECRET, Limits(slow_viewer_s=0.5))

    async def go():
        async with serving(relay) as url:
            stalled = await asyncio.to_thread(raw_viewer, url, token())
            watcher = asyncio.create_task(record(url, "lobby", token(), stream=300, timeout_s=60))
            await relay.until(viewers(relay, 2))
            for r in range(4):  # 16 raw streams a round: about 14 MB in 2 s
                await asyncio.gather(
                    *(
                        publish_clip(url, "lobby", token(), walk_bvh, get_codec("raw"), speed=8.0, stream=100 * r + s)
                        for s in range(16)
                    )
                )
            got = await watcher
            stalled.close()
            return got

    got = asyncio.run(go())
    assert relay.core.counters["missed_ticks"] > 0 and relay.core.counters["dropped_slow"] == 1
    assert got[300].num_frames == walk_bvh.num_frames  # the viewer that reads gets the last round whole


def test_the_commands_end_to_end(tmp_path):
    """serve, token, publish and subscribe as a user types them: an AMC clip recorded as BVH."""
    port = free_port()
    mocodec = [sys.executable, "-m", "mocodec"]
    server = subprocess.Popen(
        mocodec + ["serve", "--port", str(port), "--secret", SECRET], stdout=subprocess.PIPE, text=True
    )
    try:
        assert "relay on" in server.stdout.readline()
        socket.create_connection(("127.0.0.1", port), timeout=5).close()  # the line means "listening"
        tok = subprocess.run(
            mocodec + ["token", "--secret", SECRET, "--room", "r"], capture_output=True, text=True, check=True
        ).stdout.strip()
        url = f"ws://127.0.0.1:{port}"
        sub = subprocess.Popen(
            mocodec
            + [
                "subscribe",
                "--url",
                url,
                "--room",
                "r",
                "--token",
                tok,
                "-o",
                str(tmp_path / "got.bvh"),
                "--frames",
                "200",
                "--timeout",
                "60",
            ],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        assert "watching room 'r'" in sub.stderr.readline()  # in the room before anything is published
        pub = subprocess.run(
            mocodec
            + [
                "publish",
                str(DATA / "07_03.amc"),
                "--url",
                url,
                "--room",
                "r",
                "--token",
                tok,
                "--speed",
                "8",
                "--codec",
                "dpcm",
            ],
            capture_output=True,
            text=True,
        )
        assert pub.returncode == 0, pub.stderr
        out, err = sub.communicate(timeout=60)
        assert sub.returncode == 0, err
        assert "200 frames" in out
        from mocodec import load

        got = load(tmp_path / "got.bvh")
        assert got.num_frames == 200
        bad = subprocess.run(
            mocodec + ["publish", str(DATA / "07_03.amc"), "--url", url, "--room", "r", "--token", tok + "x"],
            capture_output=True,
            text=True,
        )
        assert bad.returncode == 2 and "signature" in bad.stderr and "Traceback" not in bad.stderr
    finally:
        server.terminate()
        server.wait(10)


def test_a_sender_that_vanishes_ends_its_stream_for_viewers(walk_bvh):
    packets = stream_clip(walk_bvh, get_codec("dpcm"))

    async def go():
        relay = Relay(SECRET)
        async with serving(relay) as url:
            viewer = asyncio.create_task(record(url, "lobby", token(), timeout_s=30))
            await relay.until(viewers(relay))
            async with connect(url, "lobby", token(), "publish") as ws:  # half the clip, then gone
                for p in packets[: len(packets) // 2]:
                    await ws.send_bytes(pack_batch([p.to_bytes()]))
            started = time.monotonic()
            got = await viewer
            return got, time.monotonic() - started

    (got, waited) = asyncio.run(go())
    half = packets[len(packets) // 2 - 1]
    assert got[0].num_frames == half.first_frame + half.frames and waited < 5  # ended, not timed out


def test_workers_on_a_port_in_use_say_so_and_exit():
    """A worker that cannot listen (the port is another program's) reports its error: serve
    prints it in one line and exits 2, stopping the other worker and its NATS server (it waited
    for ever for the failed worker, which printed a traceback)."""
    if shutil.which("nats-server", path="/usr/sbin:/usr/bin:/usr/local/bin") is None:
        pytest.skip("nats-server is not installed (.ci/run installs Debian's nats-server)")
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        done = subprocess.run(
            [sys.executable, "-m", "mocodec", "serve", "--port", str(port), "--secret", SECRET, "--workers", "2"],
            capture_output=True,
            text=True,
            timeout=120,
        )
    assert done.returncode == 2, done.stderr
    assert done.stderr.count("\n") == 1 and "address already in use" in done.stderr, done.stderr


def test_workers_behind_one_port_share_their_rooms(walk_bvh):
    """``serve --workers 2`` (a NATS server started by serve): the kernel spreads connections
    over both workers, and every viewer gets the stream a sender sent to whichever worker."""
    if shutil.which("nats-server", path="/usr/sbin:/usr/bin:/usr/local/bin") is None:
        pytest.skip("nats-server is not installed (.ci/run installs Debian's nats-server)")
    port = free_port()
    server = subprocess.Popen(
        [sys.executable, "-m", "mocodec", "serve", "--port", str(port), "--secret", SECRET, "--workers", "2"],
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        assert "2 workers" in server.stdout.readline()
        assert "2 workers listening" in server.stdout.readline()
        url = f"ws://127.0.0.1:{port}"

        async def go():
            joined = asyncio.Semaphore(0)
            watchers = [
                asyncio.create_task(record(url, "lobby", token(), timeout_s=60, joined=joined.release))
                for _ in range(6)
            ]
            for _ in watchers:
                await joined.acquire()
            await publish_clip(url, "lobby", token(), walk_bvh[:240], get_codec("dpcm"), speed=8)
            return await asyncio.gather(*watchers)

        got = asyncio.run(go())
    finally:
        server.terminate()
        server.wait(20)
    clean = receive_clip(stream_clip(walk_bvh[:240], get_codec("dpcm"))).channels
    for motions in got:
        np.testing.assert_array_equal(motions[0].channels, clean)

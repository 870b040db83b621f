"""The relay server, its clients and its limits, over real WebSockets on loopback."""

from __future__ import annotations

import asyncio
import contextlib
import json
import shutil
import socket
import subprocess
import sys
import time

import aiohttp
import numpy as np
import pytest

from conftest import DATA, free_port
from mocodec.cli import main
from mocodec.codecs import get_codec
from mocodec.stream import tokens
from mocodec.stream.bus import NatsBus
from mocodec.stream.client import RelayRefused, connect, publish_clip, record
from mocodec.stream.live import receive_clip, stream_clip
from mocodec.stream.packets import CUTS, Reader, pack_batch, split_batch, with_layer_ends
from mocodec.stream.relay import BAD_MESSAGE, RATE_LIMIT, Limits, Relay, Viewer, on_ladder, start

pytestmark = pytest.mark.network  # a relay (and NATS) on loopback sockets

SECRET = "test-secret"


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


async def publish_and_record(url, motion, codec, speed=8.0, **watch):
    viewer = asyncio.create_task(record(url, "lobby", token(), timeout_s=30, **watch))
    await asyncio.sleep(0.2)
    await publish_clip(url, "lobby", token(), motion, codec, speed=speed)
    return await viewer


def test_a_recorded_stream_decodes_as_offline_at_the_viewers_budget(walk_bvh):
    """spiht sent at 8 kbit/s, cut by the relay to the viewer's 3 kbit/s (rounded down to the
    relay's ladder of rates): the same motion as the clip streamed at that rate and decoded
    offline."""

    async def go():
        async with serving() as url:
            return await publish_and_record(url, walk_bvh, get_codec("spiht", bits_per_second=8000), budget=3000)

    got = asyncio.run(go())[0]
    assert 2750 < on_ladder(3000) <= 3000
    offline = receive_clip(stream_clip(walk_bvh, get_codec("spiht", bits_per_second=on_ladder(3000))))
    np.testing.assert_array_equal(got.channels, offline.channels)
    whole = receive_clip(stream_clip(walk_bvh, get_codec("spiht", bits_per_second=8000)))
    assert not np.array_equal(got.channels, whole.channels)


def test_whole_streams_pass_unchanged(walk_bvh):
    async def go():
        async with serving() as url:
            return await publish_and_record(url, walk_bvh, get_codec("dpcm"))

    got = asyncio.run(go())[0]
    np.testing.assert_array_equal(got.channels, receive_clip(stream_clip(walk_bvh, get_codec("dpcm"))).channels)


def test_late_joiner_gets_the_header_and_the_last_keyframe(walk_bvh):
    async def go():
        async with serving() as url:
            sender = asyncio.create_task(publish_clip(url, "lobby", token(), walk_bvh, get_codec("dpcm"), speed=1.0))
            await asyncio.sleep(1.6)
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


def test_repair_requests_are_checked_and_limited(walk_bvh):
    from mocodec.stream.relay import Bucket, Closing, Room
    from mocodec.stream.retention import REPAIR_PACKETS

    packets = stream_clip(walk_bvh, get_codec("kinwave-live", refresh_s=0.5), keyframe_s=60.0)[:-1]
    relay, room, viewer = Relay(SECRET), Room(), Viewer(ws=None, transport=None)
    for p in packets:
        relay._ingest(room, pack_batch([p.to_bytes()]), owner=1)
    history = room.streams[0].history
    kept = [p.sequence for p in packets[-REPAIR_PACKETS:]]  # the last REPAIR_PACKETS, restarts or not
    assert len(packets) > REPAIR_PACKETS and history.find(kept[0] - 1) is None
    assert [history.find(s).packet.sequence for s in kept] == kept
    bucket = Bucket(rate=1.0, burst_s=3.0)  # three packets
    relay._resend(viewer, room, [[0, kept[1]], [0, kept[0] - 1], [7, kept[1]], [0, kept[2]], [0, kept[3]]], bucket)
    relay._resend(viewer, room, [[0, kept[4]]], bucket)  # the bucket is empty: ignored
    assert [f.packet.sequence for f in viewer.resends] == kept[1:4] and not viewer.pending  # misses cost nothing
    assert relay.counters["repairs"] == 3 and relay.counters["repairs_missed"] == 3
    sizes = [len(history.find(s).data) for s in kept[5:8]]
    viewer.repair_volume = Bucket(rate=sum(sizes[:2]), burst_s=1.0)  # the bytes of two packets
    relay._resend(viewer, room, [[0, s] for s in kept[5:8]], Bucket(100.0, 1.0))
    assert [f.packet.sequence for f in viewer.resends[3:]] == kept[5:7]
    for bad in ([[0, -1]], [[0]], [[0, 1.5]], [["0", 1]], [[0, 1]] * 257, {"0": 1}):
        with pytest.raises(Closing, match="repair"):
            relay._resend(viewer, room, bad, Bucket(100.0, 1.0))


def _near_and_far(walk, codec, budget):
    """The walk and the same walk 20 m further along x, published at once to a viewer of
    ``budget`` bit/s standing at the near one's start: what the viewer got of each."""
    far = walk.with_channels(walk.channels.copy())
    x = walk.skeleton.channel_index("hip.Xposition")
    far.channels[:, x] += 20 * walk.skeleton.units_per_metre

    async def go():
        async with serving() as url:
            camera = tuple(walk.positions_m()[0, 0])
            viewer = asyncio.create_task(
                record(url, "lobby", token(), budget=budget, camera=camera, timeout_s=30, stream=1)
            )
            await asyncio.sleep(0.2)
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


def test_a_viewer_gains_a_layer_only_where_it_restarts(walk_bvh):
    from mocodec.stream.relay import Forward, Room, StreamState

    codec = get_codec("kinwave-live", layers=3, refresh_s=0.5)
    state = StreamState(None, None, None, codec, Room().history.stream())
    viewer = Viewer(ws=None, transport=None)

    def kept(fits, starts, keyframe=False):
        packet = stream_clip(walk_bvh[:12], codec)[1 if keyframe else 2]
        f = Forward(packet, b"", layer_ends=[1, 2, 3], layer_starts=starts)
        return Relay._layers_for(viewer, f, state, fits)

    assert kept(1, [False] * 3, keyframe=True) == 1  # the share fits the base only
    assert kept(3, [False] * 3) == 1  # room for more, but layer 1 has no history
    assert kept(3, [False, False, True]) == 1  # layer 2 cannot come without layer 1
    assert kept(3, [False, True, False]) == 2
    assert kept(3, [False, False, True]) == 3
    assert kept(2, [False] * 3) == 2  # dropping a layer needs no restart
    assert kept(1, [False] * 3) == 1


def test_a_late_joiner_of_a_refreshing_stream_starts_at_its_last_restart(walk_bvh):
    from mocodec.stream.relay import Room

    codec = get_codec("kinwave-live", refresh_s=0.25)
    packets = stream_clip(walk_bvh, codec, keyframe_s=60.0)[:-1]  # not ended
    relay, room = Relay(SECRET), Room()
    for p in packets:
        relay._ingest(room, pack_batch([p.to_bytes()]), owner=1)
    history = room.streams[0].history
    gop, _ = history.since(history.restart, float("inf"))
    last = max(i for i, p in enumerate(packets) if p.restart)
    assert gop[0].packet.restart and not gop[0].packet.keyframe
    assert [f.packet.sequence for f in gop] == [p.sequence for p in packets[last:]]


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
        payload if cuts is None else with_layer_ends(payload, cuts),
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


def test_a_slow_viewer_misses_ticks_keeps_headers_and_is_dropped():
    class StubTransport:
        aborted = False

        def abort(self):
            self.aborted = True

    async def go():
        relay = Relay(SECRET, Limits(slow_viewer_s=0.05))
        viewer = Viewer(None, StubTransport())
        viewer.queue.put_nowait((b"a batch still on its way",))
        header = type("F", (), {"packet": type("P", (), {"kind": 0})()})()
        data = type("F", (), {"packet": type("P", (), {"kind": 1})()})()
        relay._offer(viewer, (b"next",), [header, data])
        assert viewer.missed == 1 and viewer.pending == [header]  # memory stays one batch
        await asyncio.sleep(0.1)
        relay._offer(viewer, (b"next",), [data])
        relay._offer(viewer, (b"next",), [data])
        assert viewer.transport.aborted and viewer.dropped and relay.counters["dropped_slow"] == 1

    asyncio.run(go())


@pytest.fixture
def nats_server():
    binary = shutil.which("nats-server", path="/usr/sbin:/usr/bin:/usr/local/bin")
    if binary is None:
        pytest.skip("nats-server is not installed (.ci/run installs Debian's nats-server)")
    port = free_port()
    proc = subprocess.Popen(
        [binary, "-a", "127.0.0.1", "-p", str(port)], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL
    )
    for _ in range(100):
        with contextlib.suppress(OSError), socket.create_connection(("127.0.0.1", port), timeout=0.1):
            break
        time.sleep(0.05)
    yield f"nats://127.0.0.1:{port}"
    proc.terminate()
    proc.wait(5)


def test_two_relays_share_a_room_over_nats(walk_bvh, nats_server):
    """A sender on relay A reaches a viewer on relay B."""

    async def go():
        async with (
            serving(Relay(SECRET, bus=NatsBus(nats_server))) as a,
            serving(Relay(SECRET, bus=NatsBus(nats_server))) as b,
        ):
            viewer = asyncio.create_task(record(b, "lobby", token(), timeout_s=30))
            await asyncio.sleep(0.3)
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
            await asyncio.sleep(0.2)
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
    assert relay.counters["missed_ticks"] > 0 and relay.counters["dropped_slow"] == 1
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
        time.sleep(2.0)
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
        async with serving() as url:
            viewer = asyncio.create_task(record(url, "lobby", token(), timeout_s=30))
            await asyncio.sleep(0.2)
            async with connect(url, "lobby", token(), "publish") as ws:  # half the clip, then gone
                for p in packets[: len(packets) // 2]:
                    await ws.send_bytes(pack_batch([p.to_bytes()]))
            started = time.monotonic()
            got = await viewer
            return got, time.monotonic() - started

    (got, waited) = asyncio.run(go())
    half = packets[len(packets) // 2 - 1]
    assert got[0].num_frames == half.first_frame + half.frames and waited < 5  # ended, not timed out


def _ticks(relay: Relay, room, viewer: Viewer, packets, per_tick: int = 1, extra_ticks: int = 400):
    """Ingest ``packets`` ``per_tick`` a tick and dispatch each tick; then ticks without packets
    until ``viewer`` has caught up: per tick, the bytes it got and the tick's fresh bytes."""
    got = []
    for k in range(0, len(packets) + per_tick * extra_ticks, per_tick):
        chunk = packets[k : k + per_tick]
        if chunk:
            relay._ingest(room, pack_batch([p.to_bytes() for p in chunk]), owner=1)
        elif not viewer.behind:
            break
        relay._dispatch(room)
        batches = viewer.queue.get_nowait() if not viewer.queue.empty() else ()
        got.append((batches, sum(len(p.to_bytes()) for p in chunk)))
    return got


def test_a_late_viewer_catches_up_paced_and_decodes_exactly(walk_bvh):
    """A viewer joining a stream half way catches up from its keyframe at the catch-up pace
    beyond the live packets (it once got everything kept in one message), and gets every
    packet once, in order: it decodes what a viewer from the start decodes."""
    from mocodec.stream.relay import Room

    packets = stream_clip(walk_bvh, get_codec("dpcm"), keyframe_s=60.0)
    pace, tick_hz = 40_000.0, 60.0
    relay, room = Relay(SECRET, Limits(catchup_bytes_per_s=pace), tick_hz=tick_hz), Room()
    half = len(packets) // 2
    for p in packets[:half]:
        relay._ingest(room, pack_batch([p.to_bytes()]), owner=1)
    relay._dispatch(room)
    viewer = Viewer(ws=None, transport=None, queue=asyncio.Queue(maxsize=1000))
    relay._join(viewer, room)
    ticks = _ticks(relay, room, viewer, packets[half:])
    largest = max(len(p.to_bytes()) for p in packets)
    received = []
    header = len(packets[0].to_bytes())  # in the first tick's batch
    for k, (batches, live) in enumerate(ticks):
        sent = sum(len(b) for b in batches) - (header if k == 0 else 0)
        assert sent <= live + pace / tick_hz + largest + 64  # the pace, and the packet that crosses it
        received += [bytes(r) for b in batches for r in split_batch(b)]
    kept = sum(len(p.to_bytes()) for p in packets[1:half])
    assert len([t for t in ticks if t[0]]) > kept / (pace / tick_hz) / 2  # paced over many ticks
    assert received == [p.to_bytes() for p in packets]
    assert not viewer.behind and not viewer.notes


def test_what_the_relay_keeps_is_capped_per_stream_and_per_room():
    from mocodec.stream.retention import Caps, RoomHistory

    class F:
        def __init__(self, size: int, sequence: int):
            self.data, self.packet = b"x" * size, type("P", (), {"sequence": sequence})()

    room = RoomHistory(Caps(stream_bytes=1000, room_bytes=2500, stream_packets=100))
    a, b, c = room.stream(), room.stream(), room.stream()
    for k in range(50):  # a restart point at the start only
        a.add(F(100, k), restart=k == 0)
    assert a.bytes == 1000 and a.partial and a.first == 40 and room.bytes == 1000
    for k in range(10):
        b.add(F(300, k), restart=True)
    assert b.bytes == 900 and room.bytes == 1900  # the last packets for repairs, within its cap
    for k in range(20):
        c.add(F(150, k), restart=k % 5 == 0)
    assert room.bytes <= 2500 and c.bytes <= 1000 and all(h.bytes >= 0 for h in (a, b, c))
    assert a.bytes < 1000  # the room's cap took the oldest first: a's
    got, after = c.since(c.restart, 200)
    assert len(got) == 2 and after == c.first + (c.restart - c.first) + 2  # past the budget by one packet
    c.close()
    assert room.bytes == a.bytes + b.bytes and room.packets == len(a.kept) + len(b.kept)
    for k in range(10_000):  # stale entries are compacted: the queue stays in proportion
        a.add(F(10, 100 + k), restart=False)
    assert len(room.arrivals) <= 2 * room.packets + 65


@pytest.mark.parametrize("text", ["[" * 8000, '{"budget": 1e999}', '{"budget": ' + "9" * 5000 + "}"])
def test_a_viewer_message_nested_deep_or_too_large_closes_with_4400(text):
    """``'[' * 8000`` once raised RecursionError out of the handler (close code 1006)."""
    from mocodec.stream.relay import Closing

    with pytest.raises(Closing) as caught:
        Relay._settings(Viewer(ws=None, transport=None), text)
    assert caught.value.code == BAD_MESSAGE

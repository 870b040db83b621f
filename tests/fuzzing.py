"""A seeded fuzzer for everything that reads bytes from outside (docs/security.md).

``python tests/fuzzing.py TARGET SEED SECONDS`` runs one target for about SECONDS and prints a
JSON summary; it exits 1 if any input ended in anything but a clean mocodec error (or, for the
decoders, finite output of the declared shape). tests/test_fuzz.py runs every target in a child
process under a memory limit, so an unbounded allocation fails as a MemoryError instead of
taking the machine.

Inputs: random bytes, truncations, bit flips and byte changes of valid inputs, with their CRCs
recomputed (else the CRC rejects nearly everything and the parsers behind it go untested), and
crafted ones: decompression bombs and huge declared sizes.
"""

from __future__ import annotations

import io
import json
import re
import struct
import sys
import time
import traceback
import zlib
from pathlib import Path

import numpy as np

HERE = Path(__file__).parent
sys.path.insert(0, str(HERE))

from mocodec import limits, load, moc, reexpress  # noqa: E402
from mocodec.codecs import Codec, codec_ids, get_codec  # noqa: E402
from mocodec.errors import CorruptStreamError, MocodecError  # noqa: E402
from mocodec.formats import container  # noqa: E402
from mocodec.formats.amc import read_amc  # noqa: E402
from mocodec.formats.asf import read_asf  # noqa: E402
from mocodec.formats.header_dict import DICTIONARIES  # noqa: E402
from mocodec.stream.live import LiveDecoder, stream_clip  # noqa: E402
from mocodec.stream.packets import HEADER, Packet, Reader, StreamInfo, pack_batch, parse, split_batch  # noqa: E402
from mocodec.stream.relay import Bucket, Closing, Limits, RelayCore, Room, Viewer  # noqa: E402

DATA = HERE / "data"
#: Codecs whose decoders need a model file the fuzzer has not got; their payloads still go
#: through the container and the stream checks.
NEEDS_FILES = {"rhythmic", "posture", "gesture", "hybrid"}
#: Seconds a structure case may take: far above what a linear reader needs, far below what a
#: quadratic one took (docs/security.md).
BOUND_S = 20.0


def mutate(data: bytes, rng: np.random.Generator) -> bytes:
    """One random change: flipped bits, changed or inserted bytes, a cut, or a spliced copy."""
    data = bytearray(data)
    kind = rng.integers(6)
    if not data or kind == 0:
        return bytes(rng.integers(0, 256, int(rng.integers(0, 64)), dtype=np.uint8))
    if kind == 1:
        for at in rng.integers(0, len(data), int(rng.integers(1, 8))):
            data[at] ^= 1 << int(rng.integers(8))
    elif kind == 2:
        for at in rng.integers(0, len(data), int(rng.integers(1, 4))):
            data[at] = int(rng.choice([0, 1, 0x7F, 0x80, 0xFF, int(rng.integers(256))]))
    elif kind == 3:
        del data[int(rng.integers(len(data))) :]
    elif kind == 4:
        at = int(rng.integers(len(data) + 1))
        data[at:at] = bytes(rng.integers(0, 256, int(rng.integers(1, 16)), dtype=np.uint8))
    else:
        a, b = sorted(rng.integers(0, len(data) + 1, 2))
        data[a:a] = data[a:b]
    return bytes(data)


def clean(call) -> str | None:
    """None if ``call()`` returns or raises a mocodec error; else what went wrong."""
    try:
        call()
    except MocodecError as e:
        if "MemoryError" in str(e):
            return f"MemoryError inside {type(e).__name__}: {e}"
        return None
    except Exception:  # noqa: BLE001 - the fuzzer's whole point
        return traceback.format_exc(limit=-3)
    return None


class Run:
    def __init__(self, seed: int, seconds: float):
        self.rng = np.random.default_rng(seed)
        self.seconds = seconds
        self.deadline: float | None = None  # the clock starts at the first case, after the set-up
        self.cases = 0
        self.failures: list[str] = []

    def more(self) -> bool:
        if self.deadline is None:
            self.deadline = time.monotonic() + self.seconds
        return time.monotonic() < self.deadline

    def check(self, what: str, call) -> None:
        self.cases += 1
        problem = clean(call)
        if problem and len(self.failures) < 20:
            self.failures.append(f"{what}: {problem}")


def _walk():
    return load(DATA / "07_03.bvh")[:96]


def _decoded_ok(codec: Codec, body: bytes, motion) -> None:
    out = codec.decode(body, motion.skeleton, motion.num_frames, motion.fps)
    if not np.isfinite(out.channels).all():
        raise AssertionError("non-finite output")


# ----- targets ----------------------------------------------------------------------------------
def fuzz_decoders(run: Run) -> None:
    """Every codec's decoder on mutated bodies (what passes a container's or a packet's CRC
    when the writer itself is hostile)."""
    walk = _walk()
    turned = reexpress.with_dummy_root(walk, (0.0, 90.0, 0.0))  # kinwave's WORLD forms and world-axis translations
    payloads = {}
    for cid in codec_ids():
        try:
            payloads[cid] = get_codec(cid).encode(walk), walk
        except MocodecError:
            continue  # an optional package is missing
    payloads["kinwave under a turned dummy"] = get_codec("kinwave").encode(turned), turned
    while run.more():
        for name, (body, motion) in payloads.items():
            damaged = mutate(body, run.rng)
            codec = get_codec(name.split()[0])
            run.check(f"{name} decoder", lambda: _decoded_ok(codec, damaged, motion))


def fuzz_container(run: Run) -> None:
    """.moc files: mutated whole files, mutated headers with their CRC recomputed, bombs and
    huge declared sizes."""
    walk = _walk()
    files = [moc.pack(walk, get_codec(c), chunk_frames=40) for c in ("kinwave", "raw", "lossless", "spiht")]
    files.append(moc.pack(walk[:40], get_codec("kinwave")))  # one chunk: no index
    while run.more():
        data = files[int(run.rng.integers(len(files)))]
        run.check("moc file", lambda: moc.unpack(mutate(data, run.rng)))
        version, flags, head_at, head_len = container.read_opening(io.BytesIO(data), len(data), "fuzz")
        head = data[head_at : head_at + head_len]
        text = zlib.decompressobj(zdict=DICTIONARIES[version]).decompress(head)
        meta, _, compact = text.partition(b"\0")
        choice = run.rng.integers(3)
        if choice == 0:
            new_text = mutate(meta, run.rng) + b"\0" + compact
        elif choice == 1:
            new_text = meta + b"\0" + mutate(compact, run.rng)
        else:
            doc = json.loads(meta)
            key = str(run.rng.choice(["frames", "fps", "chunk_frames", "codec"]))
            values = (
                [
                    {"codec": "raw", "knobs": [1]},
                    {"codec": "raw", "knobs": "x"},
                    {"codec": {}},
                    [],
                    {"codec": "svq", "knobs": {"codebook": "/dev/zero"}},
                ]
                if key == "codec"
                else [2**32, 2**20, -1, 1e8, 1e-300, "x", [1], {}, None]
            )
            doc[key] = values[int(run.rng.integers(len(values)))]
            new_text = json.dumps(doc).encode() + b"\0" + compact
        deflate = zlib.compressobj(9, zdict=DICTIONARIES[version])
        new_head = deflate.compress(new_text) + deflate.flush()
        forged = (
            container.opening(version, flags, len(new_head))
            + new_head
            + struct.pack("<I", zlib.crc32(new_head))
            + data[head_at + head_len + 4 :]
        )
        run.check("moc header", lambda: moc.unpack(forged))
    bomb = zlib.compress(b"{" + b" " * (64 << 20), 9)
    forged = container.opening(container.VERSION, 0, len(bomb)) + bomb + struct.pack("<I", zlib.crc32(bomb))
    run.check("moc header bomb", lambda: moc.unpack(forged + files[0][-40:]))


def _packets():
    walk = _walk()
    return [
        stream_clip(walk, get_codec(c)) for c in ("dpcm", "spiht", "kinwave", "kinwave-live", "primitives", "adpcm")
    ]


def _reframed(p: Packet, rng) -> Packet:
    """``p`` with its payload or one header field changed (the CRC is recomputed on send)."""
    field = rng.integers(4)
    if field == 0:
        return p.with_payload(mutate(p.payload, rng), p.flags)
    if field == 1:
        return Packet(
            p.stream,
            p.sequence,
            p.timestamp_us,
            p.codec,
            int(rng.choice([0, 2**32 - 200, 2**31, p.first_frame + 1])),
            p.frames,
            p.payload,
            p.kind,
            p.flags,
            p.position,
        )
    if field == 2:
        return Packet(
            p.stream,
            p.sequence,
            p.timestamp_us,
            p.codec,
            p.first_frame,
            int(rng.integers(0, 2**16)),
            p.payload,
            p.kind,
            int(rng.integers(0, 8)),
            p.position,
        )
    return Packet(
        p.stream,
        int(rng.integers(0, 2**32)),
        p.timestamp_us,
        p.codec,
        p.first_frame,
        p.frames,
        p.payload,
        p.kind,
        p.flags,
        (float("nan"), 1e38, -0.0),
    )


def _reader_after(header: Packet) -> Reader:
    """A receiver that has read ``header`` (compact packets follow on from it)."""
    reader = Reader()
    reader.read(header.to_bytes())
    return reader


def fuzz_live(run: Run) -> None:
    """The packet parser, stream headers and LiveDecoder on mutated packets."""
    streams = _packets()
    while run.more():
        packets = streams[int(run.rng.integers(len(streams)))]
        raw = packets[int(run.rng.integers(len(packets)))].to_bytes()
        run.check("packet parser", lambda: parse(mutate(raw, run.rng)))
        run.check("compact packet reader", lambda: _reader_after(packets[0]).read(mutate(raw, run.rng)))
        run.check("batch parser", lambda: split_batch(mutate(pack_batch([raw, raw]), run.rng)))
        run.check("stream header", lambda: LiveDecoder(StreamInfo.from_payload(mutate(packets[0].payload, run.rng))))

        def play():
            dec = LiveDecoder(StreamInfo.from_payload(packets[0].payload))
            reader = _reader_after(packets[0])
            for p in packets[1:]:
                if run.rng.random() < 0.3:
                    p = _reframed(p, run.rng)
                try:
                    got = reader.read(p.to_bytes())
                except CorruptStreamError:
                    continue  # refused by the framing: the decoder conceals the gap
                out = dec.push(got)
                if out.shape[1:] != (dec.info.skeleton.num_channels,):
                    raise AssertionError(f"LiveDecoder returned {out.shape}")

        run.check("LiveDecoder", play)


def _big_stream(rng, packets: int) -> list[Packet]:
    """A stream of 60 KB packets that never restarts (a header, then data)."""
    header = stream_clip(_walk()[:10], get_codec("dpcm"))[0]
    out = [Packet(5, 0, 0, "dpcm", 0, 0, header.payload, kind=HEADER)]
    return out + [Packet(5, k, 0, "dpcm", 4 * k, 4, rng.bytes(60_000)) for k in range(1, packets)]


def _late_viewers_and_repairs(relay: RelayCore, room: Room, rng) -> None:
    """A late viewer joins, another asks for random packets again; what the room keeps and
    what any viewer is sent in one tick stay within the caps (an AssertionError otherwise)."""
    viewer = Viewer(budget=float(rng.choice([0, 4000])))
    relay.join(room, viewer)
    pairs = [
        [int(rng.choice(list(room.streams) or [0])), int(rng.integers(0, 64))] for _ in range(int(rng.integers(1, 40)))
    ]
    try:
        relay.resend(room, viewer, pairs, Bucket(1e9, 1.0))
    except Closing:
        pass
    relay.dispatch(room)
    assert room.history.bytes <= relay.limits.max_room_kept_bytes, "the room keeps more than its cap"
    for v in room.viewers:
        while v.outbox:
            sent = sum(len(b) for b in v.outbox.popleft())
            assert sent <= 2 * relay.limits.max_message_bytes + 2 * relay.limits.max_stream_kept_bytes, sent
    relay.leave(room, viewer)


def fuzz_relay(run: Run) -> None:
    """The relay's message handler and its tick on mutated batches from publishers, with a
    viewer that has a budget (so packets are cut); late viewers joining and repair requests,
    with streams of large packets that never restart among them."""
    streams = _packets() + [_big_stream(run.rng, 40)]
    relay = RelayCore(Limits(max_stream_kept_bytes=1 << 20, max_room_kept_bytes=2 << 20))
    while run.more():
        relay.rooms.pop("fuzz", None)
        room = relay.room("fuzz")
        relay.join(room, Viewer(budget=float(run.rng.choice([0, 2000, 9000]))))
        packets = streams[int(run.rng.integers(len(streams)))]
        owner = object()
        for k in range(0, len(packets), 3):
            group = [
                _reframed(p, run.rng) if run.rng.random() < 0.3 and p.kind != HEADER else p for p in packets[k : k + 3]
            ]
            data = pack_batch([p.to_bytes() for p in group])
            if run.rng.random() < 0.2:
                data = mutate(data, run.rng)

            def ingest():
                try:
                    relay.ingest(room, data, owner)
                except Closing:
                    pass
                relay.dispatch(room)
                room.viewers[0].outbox.clear()
                if run.rng.random() < 0.3:
                    _late_viewers_and_repairs(relay, room, run.rng)

            run.check("relay", ingest)


def _text_mutation(text: str, rng) -> str:
    lines = text.split("\n")
    for _ in range(int(rng.integers(1, 4))):
        k = int(rng.integers(len(lines)))
        kind = rng.integers(5)
        if kind == 0:
            del lines[k]
        elif kind == 1:
            lines.insert(k, lines[int(rng.integers(len(lines)))])
        elif kind == 2:
            toks = lines[k].split()
            if toks:
                toks[int(rng.integers(len(toks)))] = str(
                    rng.choice(
                        [
                            "nan",
                            "inf",
                            "1e-320",
                            "1e400",
                            "-0",
                            "²",
                            "9" * 5000,
                            "",
                            "{",
                            "}",
                            "End",
                            "root",
                            "rx",
                            "CHANNELS",
                            "99999999999",
                            "-1",
                        ]
                    )
                )
                lines[k] = " ".join(toks)
        elif kind == 3:
            lines[k] = lines[k][: int(rng.integers(len(lines[k]) + 1))]
        else:
            lines[k] = mutate(lines[k].encode("latin-1", "replace"), rng).decode("latin-1")
    return "\n".join(lines)


def fuzz_parsers(run: Run, folder: Path) -> None:
    """BVH, ASF and AMC readers on mutated text."""
    bvh = (DATA / "09_02.bvh").read_text()
    bvh = "\n".join(bvh.split("\n")[:400])
    header, frames = bvh.split("MOTION")
    bvh = header + "MOTION\n" + re.sub(r"Frames:\s*\d+", "Frames: 20", frames.split("\n", 1)[1])
    bvh = "\n".join(bvh.split("\n")[: bvh.split("\n").index("Frames: 20") + 22])
    asf = (DATA / "07.asf").read_text()
    amc = "\n".join((DATA / "07_03.amc").read_text().split("\n")[:200])
    (folder / "good.asf").write_text(asf)
    while run.more():
        (folder / "x.bvh").write_text(_text_mutation(bvh, run.rng), encoding="latin-1")
        run.check("bvh", lambda: load(folder / "x.bvh"))
        (folder / "x.asf").write_text(_text_mutation(asf, run.rng), encoding="latin-1")
        run.check("asf", lambda: read_asf(folder / "x.asf"))
        (folder / "x.amc").write_text(_text_mutation(amc, run.rng), encoding="latin-1")
        run.check("amc", lambda: read_amc(folder / "x.amc", folder / "good.asf"))


def _json_mutation(value, rng):
    """``value`` (parsed JSON) with one random member replaced by a hostile value: a huge,
    negative or fractional number, a string, a list, an object or null."""
    holders = []
    stack = [value]
    while stack:
        item = stack.pop()
        keys = list(item) if isinstance(item, dict) else range(len(item)) if isinstance(item, list) else []
        for key in keys:
            holders.append((item, key))
            stack.append(item[key])
    if not holders:
        return value
    holder, key = holders[int(rng.integers(len(holders)))]
    choices = [2**31, 2**53, -1, 0, 1, 0.5, 1e308, "x", [], [0, 0], {}, None, [[0]], 10**6]
    holder[key] = choices[int(rng.integers(len(choices)))]
    return value


def _gltf_structure(path: Path, rng) -> None:
    """A glTF of hostile structure: a node chain of random depth (past MAX_DEPTH too), many
    nodes, channels sharing one accessor, accessors declaring huge counts with or without
    data, JSON nested deep in extras; read within BOUND_S (an AssertionError otherwise)."""
    from gltf_builder import chain_glb, glb_bytes

    g = chain_glb(int(rng.choice([2, 50, 3000, limits.MAX_DEPTH + 10])))
    animation = g.doc["animations"][0]
    if rng.random() < 0.3:  # many channels, one accessor
        animation["channels"] *= int(rng.integers(2, 2000))
    if rng.random() < 0.3:  # a count from nowhere, or past its data
        accessor = g.doc["accessors"][int(rng.integers(len(g.doc["accessors"])))]
        accessor["count"] = int(rng.choice([2**20, 2**24, 2**31]))
        if rng.random() < 0.5:
            accessor.pop("bufferView", None)
    if rng.random() < 0.2:
        g.doc["nodes"] += [{"name": "x"}] * int(rng.choice([1000, 70_000]))
    g.glb()  # the buffer's length into the document
    text = json.dumps(g.doc)
    if rng.random() < 0.2:
        nesting = int(rng.choice([500, 5000, 50_000]))
        text = text.replace('"asset": {', '"asset": {"extras": ' + "[" * nesting + "]" * nesting + ", ", 1)
    data = glb_bytes(text.encode(), g.blob)
    path.write_bytes(data)
    start = time.monotonic()
    try:
        load(path)
    finally:
        assert time.monotonic() - start < BOUND_S, f"a {len(data)}-byte glTF took over {BOUND_S} s"


def _fbx_take(rng) -> str:
    """An ASCII FBX chain of random depth whose take lasts from a second to 50,000 s."""
    from fbx_chain import chain_fbx

    return chain_fbx(int(rng.choice([2, 40, limits.MAX_DEPTH + 10])), float(rng.choice([1, 600, 50_000])))


def fuzz_formats(run: Run, folder: Path) -> None:
    """The glTF reader (mutated .glb bytes, and mutated values in its JSON), the FBX reader
    (mutated ASCII FBX) and the numcodecs codec's chunks (mutated, CRC recomputed)."""
    from mocodec.formats.gltfwrite import to_gltf_bytes

    glb = to_gltf_bytes(_walk()[:8], binary=True)
    json_size = struct.unpack_from("<I", glb, 12)[0]
    document, blob = json.loads(glb[20 : 20 + json_size]), glb[20 + json_size :]
    fbx = (HERE / "formats" / "fbx" / "nod.fbx").read_bytes()
    chunk_codec = None
    try:
        from mocodec.numcodecs import Kinwave

        chunk_codec = Kinwave.for_motion(_walk(), max_error_cm=1.0)
        chunk = chunk_codec.encode(_walk().channels[:48])
    except MocodecError:  # the [zarr] extra is missing: its target is skipped
        pass
    while run.more():
        (folder / "x.glb").write_bytes(mutate(glb, run.rng))
        run.check("glb bytes", lambda: load(folder / "x.glb"))
        text = json.dumps(_json_mutation(json.loads(json.dumps(document)), run.rng)).encode()
        text += b" " * (-len(text) % 4)
        (folder / "y.glb").write_bytes(
            struct.pack("<4sII", b"glTF", 2, 20 + len(text) + len(blob))
            + struct.pack("<I", len(text))
            + b"JSON"
            + text
            + blob
        )
        run.check("glTF values", lambda: load(folder / "y.glb"))
        if run.rng.random() < 0.1:  # each FBX read forks the loader's child
            (folder / "x.fbx").write_bytes(mutate(fbx, run.rng))
            run.check("fbx", lambda: load(folder / "x.fbx", fps=8))
        run.check("glTF structure", lambda: _gltf_structure(folder / "s.glb", run.rng))
        if run.rng.random() < 0.03:  # each FBX read forks the loader's child
            (folder / "t.fbx").write_text(_fbx_take(run.rng))
            run.check("FBX take", lambda: load(folder / "t.fbx"))
        if chunk_codec is not None:
            framed = mutate(chunk[:-4], run.rng)
            damaged = framed + zlib.crc32(framed).to_bytes(4, "little")
            run.check("numcodecs chunk", lambda: chunk_codec.decode(damaged))
            shape = (int(run.rng.choice([1, 47, 48, 49, 4096])), chunk_codec.skeleton.num_channels)
            run.check("numcodecs chunk shape", lambda: chunk_codec.decode(chunk, out=np.zeros(shape, "f4")))
            config = _json_mutation(chunk_codec.get_config(), run.rng)
            run.check("numcodecs config", lambda: Kinwave.from_config(config))


TARGETS = {
    "decoders": fuzz_decoders,
    "container": fuzz_container,
    "live": fuzz_live,
    "relay": fuzz_relay,
    "parsers": fuzz_parsers,
    "formats": fuzz_formats,
}


def main(argv: list[str]) -> int:
    import tempfile

    target, seed, seconds = argv[0], int(argv[1]), float(argv[2])
    run = Run(seed, seconds)
    if target in ("parsers", "formats"):
        with tempfile.TemporaryDirectory() as folder:
            TARGETS[target](run, Path(folder))
    else:
        TARGETS[target](run)
    print(json.dumps({"target": target, "cases": run.cases, "failures": run.failures}))
    return 1 if run.failures else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

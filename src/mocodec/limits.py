"""How much a file or a stream may make mocodec allocate (docs/security.md).

A coded motion says how many frames it holds and at what rate; a damaged or hostile one can
claim anything, and a wavelet or model codec turns a few bytes into as many frames as it is
told. Every reader checks the declared sizes against these limits before it allocates, and
refuses with a one-line :class:`~mocodec.errors.CorruptStreamError` naming the limit and how to
raise it. Decoding functions take the limit as an argument (``max_values``), and the command
line as ``--max-values``.
"""

from __future__ import annotations

#: Decoded values (frames x channels) one decode may produce: 2**25 values are 256 MiB of
#: float64, 35 minutes of a 132-channel skeleton at 120 fps.
MAX_DECODED_VALUES = 1 << 25
#: Frames in one codec payload (one .moc chunk): 2.4 hours at 120 fps; the container chunks clips.
MAX_PAYLOAD_FRAMES = 1 << 20
#: The highest frame rate a file or stream may declare (Hz): sensors run at hundreds.
MAX_FPS = 10_000.0
#: Bytes a compressed header (a .moc header, a stream header) may inflate to.
MAX_HEADER_TEXT = 8 << 20
#: Joints a skeleton from a file or a stream may have.
MAX_JOINTS = 1 << 16
#: How deep a glTF or FBX node tree may nest (a real skeleton is tens deep; a chain of
#: thousands is an attack on the time a reader spends per level).
MAX_DEPTH = 4096
#: Nodes x frames a reader may evaluate: an FBX take is sampled by evaluating every node of the
#: scene at each frame (about 4 us each, so at most about 17 s); give a lower fps for more.
MAX_NODE_FRAMES = 1 << 22
#: The lowest frame rate a file or stream may declare (Hz): a frame every 17 minutes.
MIN_FPS = 1e-3
#: The frame rates a file or stream may declare, as a message says it.
FPS_RANGE = f"[{MIN_FPS:g}, {MAX_FPS:g}]"


def fps_ok(fps: float) -> bool:
    """Whether a declared frame rate is within [MIN_FPS, MAX_FPS] (finite)."""
    return MIN_FPS <= fps <= MAX_FPS

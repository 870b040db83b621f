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

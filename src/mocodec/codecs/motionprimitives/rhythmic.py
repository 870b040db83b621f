"""``rhythmic``: the rhythmic-motion framework of 001 ch. 4: whole-body segments replaced by
references to primitives, decoded by temporal blending.

The motion is cut at whole-body key poses into segments of 15 to ``max_segment`` frames
(:mod:`mocodec.codecs.motionprimitives.rhythmdb`); each segment is sent as the index of the closest primitive
(the sum over joints of distance (5.4)) and its length, nothing else: no residual, so the
error is whatever the closest primitive's is. The decoder plays the primitives resampled to
those lengths and blends them at the seams (slerp over a transition found by a distance map,
the root re-placed by blended velocity: :mod:`mocodec.codecs.motionprimitives.blend`, 4.2.2).

The primitives come from a database both ends hold (``db``: a file from ``mocodec rhythm
train``, named in the body by fingerprint) or, with ``db`` empty, are ``primitives``
k-medoids of the clip's own segments, carried in the body in compact form: the setting of
the thesis's table 4.1, whose ratios count the database. More primitives is better quality
and a larger body: ``primitives`` is the quality knob.

Ch. 4 is a storage framework for long sequences; it does not claim real time, and the
database made from the clip needs the whole clip: the codec does not stream.
"""

from __future__ import annotations

import struct

import numpy as np

from mocodec.codecs.base import Codec, Knob, QualityKnob, continuous_frames
from mocodec.codecs.motionprimitives import blend, quatseg, rhythmdb
from mocodec.codecs.registry import register
from mocodec.coding.entropy.parts import join_parts, split_parts
from mocodec.coding.entropy.rangecoder import decode_ints, encode_ints
from mocodec.errors import CodecError, CorruptStreamError
from mocodec.skeleton import Skeleton

_PARTS = 4
CARRIED, EXTERNAL = b"c", b"x"  # first byte of the database part


def _key_step(skeleton: Skeleton) -> float:
    """Quantisation step of the root keys: a thousandth of the figure's height (about 2 mm)."""
    return max(skeleton.height(), 1e-6) / 1000.0


@register
class RhythmicCodec(Codec):
    id = "rhythmic"
    description = "rhythmic motion: whole-body segments replaced by primitive references, blended on decode"
    knobs = (
        Knob(
            "primitives", int, rhythmdb.COUNT, "primitives made from the clip and carried (db empty)", low=1, high=4096
        ),
        Knob("max_segment", int, 32, "longest segment in frames", low=quatseg.MIN_SEGMENT, high=256),
        Knob(
            "db", str, "", "a rhythm database file (mocodec model train rhythm); empty: made from the clip", path=True
        ),
        Knob("blend", bool, True, "blend consecutive segments (4.2.2); false: butt them together"),
        Knob(
            "root",
            str,
            "keys",
            "keys: root position sent at every seam; velocity: from the primitives (4.2.2)",
            choices=("keys", "velocity"),
        ),
    )
    quality = QualityKnob("primitives", higher_is_better=True, log_scale=True)

    def _encode(self, motion) -> bytes:
        lay, sk = quatseg.layout(motion.skeleton), motion.skeleton
        cuts, rot, root = rhythmdb.segments(motion, self.config["max_segment"])
        if self.config["db"]:
            db = self._external(lay, sk, motion.fps)
            carried = EXTERNAL + struct.pack("<I", db.fingerprint)
        else:
            db = rhythmdb.from_segments(
                lay.names,
                rot,
                root,
                cuts[:, 1] - cuts[:, 0],
                motion.fps,
                self.config["primitives"],
                self.config["max_segment"],
                0,
                [],
            ).as_compact(lay, motion.fps)
            carried = CARRIED + db.compact()
        index = np.argmin(rhythmdb.body_distance(rot, db.rotations), axis=1)
        if self.config["root"] == "keys":
            at = np.append(cuts[:, 0], motion.num_frames - 1)
            keys = np.round(motion.channels[at][:, lay.translation] / _key_step(sk)).astype(np.int64)
            placed = encode_ints(np.diff(keys, axis=0, prepend=0))
        else:
            placed = motion.channels[0, lay.translation].astype("<f4").tobytes()
        return join_parts([encode_ints(cuts[:, 1] - cuts[:, 0]), encode_ints(index), placed, carried])

    def _decode(self, body: bytes, skeleton: Skeleton, frames: int, fps: float) -> np.ndarray:
        where = "rhythmic body"
        lay = quatseg.layout(skeleton)
        parts = split_parts(body, _PARTS, where)
        lengths, index = decode_ints(parts[0]), decode_ints(parts[1])
        db = self._carried(parts[3], lay, skeleton, fps, where)
        if lengths.size != index.size or lengths.min(initial=1) < 1 or lengths.sum() != frames:
            raise CorruptStreamError(f"{where}: segment lengths do not add up to the {frames} frames of the header")
        if index.min(initial=0) < 0 or index.max(initial=0) >= db.count:
            raise CorruptStreamError(f"{where}: a primitive index is out of range (the database has {db.count})")
        q = blend.play(db.rotations[index], lengths)
        seams = blend.transitions(skeleton, lay, q, lengths) if self.config["blend"] else np.zeros((0, 3), np.int64)
        q = blend.blend_rotations(q, seams)
        path = blend.paths(db.root[index], lengths)
        width = len(lay.translation)
        if self.config["root"] == "keys":
            keys = decode_ints(parts[2])
            if keys.size != width * (len(lengths) + 1):
                raise CorruptStreamError(f"{where}: {keys.size} root key values for {len(lengths)} segments")
            keys = np.cumsum(keys.reshape(len(lengths) + 1, width), axis=0) * _key_step(skeleton)
            translation = blend.keyed_root(path, lengths, keys)
        else:
            if len(parts[2]) != 4 * width:
                raise CorruptStreamError(f"{where}: a {len(parts[2])}-byte start does not match the skeleton")
            translation = blend.velocity_root(
                path, lengths, rhythmdb.vertical(skeleton), np.frombuffer(parts[2], "<f4").astype(np.float64), seams
            )
        channels = quatseg.quaternions_to_channels(lay, q, translation, skeleton.num_channels)
        return continuous_frames(self.id, skeleton, fps, channels, None)

    def _external(self, lay: quatseg.Layout, skeleton: Skeleton, fps: float) -> rhythmdb.RhythmDB:
        db = rhythmdb.RhythmDB.load(self.config["db"])
        db.check(lay, len(lay.translation), fps, f"rhythm database {self.config['db']}")
        return db

    def _carried(self, part: bytes, lay, skeleton, fps, where) -> rhythmdb.RhythmDB:
        kind, rest = part[:1], part[1:]
        if kind == CARRIED:
            if self.config["db"]:
                raise CodecError(f"{where}: the motion carries its own primitives; drop --db")
            return rhythmdb.RhythmDB.from_compact(
                rest, lay, len(lay.translation), fps, self.config["max_segment"], where
            )
        if kind != EXTERNAL or len(rest) != 4:
            raise CorruptStreamError(f"{where}: the database part is neither primitives nor a fingerprint")
        (fingerprint,) = struct.unpack("<I", rest)
        if not self.config["db"]:
            raise CodecError(
                f"{where}: the motion was coded with rhythm database {fingerprint:08x}; none is given (--db FILE)"
            )
        db = self._external(lay, skeleton, fps)
        if db.fingerprint != fingerprint:
            raise CodecError(
                f"{where}: the motion was coded with rhythm database {fingerprint:08x}; "
                f"{self.config['db']} is {db.fingerprint:08x}"
            )
        return db

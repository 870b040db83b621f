"""What the viewer shows: a clip, its coded version, and the numbers between them.

A :class:`ViewSession` holds the reference motion (a BVH or ASF/AMC clip, or the motion a
.moc file decodes to) and, after :meth:`ViewSession.code`, its decoded version under a codec
and knobs or a rate-control target. :meth:`ViewSession.state` is the JSON the page draws: the
bones, the global joint positions and orientations of both motions (metres and quaternions,
computed here by forward kinematics, so the page needs no kinematics of its own), the
skeleton's mannequin (:mod:`mocodec.mannequin`, which the page skins with them), the joint
position error of every joint in every frame (cm), and the headline numbers (ratio, bit rate,
PSNR, VPSNR, joint errors).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from mocodec import moc, ratecontrol
from mocodec.codecs import Codec, codec_class, codec_ids, get_codec
from mocodec.errors import CodecError
from mocodec.formats import load
from mocodec.formats.pagejson import base64_f32, body_or_none, orientations
from mocodec.metrics import compare
from mocodec.motion import Motion


def load_reference(path: str | Path, asf: str | None = None) -> Motion:
    """The motion a file holds: a clip, or what a .moc file decodes to."""
    path = Path(path)
    if path.suffix.lower() == ".moc":
        return moc.decode(path)
    return load(path, asf=asf)


@dataclass
class Coded:
    codec: Codec
    decoded: Motion
    numbers: dict
    positions: np.ndarray  # the decoded motion's joint positions, metres
    quats: str  # ... and its joints' rotations, as the page takes them (orientations)


class ViewSession:
    def __init__(self, motion: Motion, name: str = ""):
        self.motion, self.name = motion, name
        self.positions = motion.positions_m()
        self.quats = orientations(motion)
        self.body = body_or_none(motion.skeleton, motion.channels[0] if motion.num_frames else None)
        self.coded: Coded | None = None

    def code(self, codec_id: str, knobs: dict | None = None, target: tuple[str, float] | None = None) -> Coded:
        """Encode and decode the reference (rate control finds the knob for ``target``)."""
        codec = get_codec(codec_id, **(knobs or {}))
        if target is not None:
            kind, value = target
            if kind not in ratecontrol.TARGETS:
                raise CodecError(f"unknown target {kind!r} (targets: {', '.join(ratecontrol.TARGETS)})")
            codec = ratecontrol.configure(codec, self.motion, kind, float(value))
        trip = moc.round_trip(self.motion, codec)
        s = compare(self.motion, trip.decoded).summary()
        m = self.motion
        numbers = {
            "codec": repr(codec),
            "bytes": len(trip.data),
            "ratio": m.raw_bits / 8 / len(trip.data),
            "bits_per_second": len(trip.data) * 8 / m.duration,
            "psnr_db": s["psnr_db"],
            "vpsnr_db": s["vpsnr_db"],
            "mean_joint_error_cm": s["mean_joint_error_cm"],
            "max_joint_error_cm": s["max_joint_error_cm"],
        }
        self.coded = Coded(
            codec,
            trip.decoded,
            {k: _finite(v) for k, v in numbers.items()},
            trip.decoded.positions_m(),
            orientations(trip.decoded),
        )
        return self.coded

    def state(self) -> dict:
        sk, m = self.motion.skeleton, self.motion
        out = {
            "name": self.name,
            "fps": m.fps,
            "frames": m.num_frames,
            "joints": list(sk.names),
            "parents": [int(p) for p in sk.parents],
            "original": base64_f32(self.positions),
            "original_quats": self.quats,
            "body": self.body,
            "decoded": None,
            "decoded_quats": None,
            "error_cm": None,
            "numbers": None,
            "config": None,
        }
        if self.coded is not None:
            decoded = self.coded.positions
            error_cm = np.linalg.norm(decoded - self.positions, axis=2) * 100
            out.update(
                decoded=base64_f32(decoded),
                decoded_quats=self.coded.quats,
                error_cm=base64_f32(error_cm),
                numbers=self.coded.numbers,
                config=self.coded.codec.get_config(),
            )
        return out


def _finite(v):
    return None if isinstance(v, float) and not np.isfinite(v) else v


def codec_menu() -> list[dict]:
    """Every codec with its knobs, for the page's controls."""
    out = []
    for cid in codec_ids():
        cls = codec_class(cid)
        out.append(
            {
                "id": cid,
                "description": cls.description,
                "baseline": bool(cls.baseline),
                "quality": cls.quality.name if cls.quality else None,
                "knobs": [
                    {
                        "name": k.name,
                        "type": k.kind.__name__,
                        "default": k.default,
                        "help": k.help,
                        "low": k.low,
                        "high": k.high,
                        "choices": list(k.choices) if k.choices else None,
                    }
                    for k in cls.knobs
                ],
            }
        )
    return out

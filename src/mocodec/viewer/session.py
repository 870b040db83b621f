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

import base64
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from mocodec import mannequin, moc, ratecontrol
from mocodec.codecs import Codec, codec_class, codec_ids, get_codec
from mocodec.errors import CodecError, MocodecError
from mocodec.formats import load
from mocodec.formats.container import skeleton_from_dict
from mocodec.kinematics import forward_kinematics
from mocodec.metrics import compare
from mocodec.motion import Motion
from mocodec.skeleton import Skeleton


def base64_f32(values: np.ndarray) -> str:
    """An array as base64 little-endian float32 (compact for the page, decoded with atob)."""
    return base64.b64encode(np.ascontiguousarray(values, dtype="<f4").tobytes()).decode()


def base64_u32(values: np.ndarray) -> str:
    """An array of indices as base64 little-endian uint32."""
    return base64.b64encode(np.ascontiguousarray(values, dtype="<u4").tobytes()).decode()


def orientations(motion: Motion) -> str:
    """Every joint's global orientation in every frame as base64 float32 quaternions in
    three.js's order (x, y, z, w)."""
    return base64_f32(forward_kinematics(motion.skeleton, motion.channels)[1][..., [1, 2, 3, 0]])


def body_of(skeleton: Skeleton, first_frame: np.ndarray | None = None, level: int = 0) -> dict:
    """A skeleton's mannequin for the page: bind-pose positions (metres), normals, triangles,
    four joints and weights a vertex, the joint whose error paints each vertex, and the bind
    pose's joint positions (:func:`mocodec.mannequin.bind_positions` of ``first_frame``)."""
    bind = mannequin.bind_positions(skeleton, first_frame)
    body = mannequin.build(skeleton, bind, level)
    metre = skeleton.units_per_metre
    return {
        "positions": base64_f32(body.positions / metre),
        "normals": base64_f32(body.normals),
        "triangles": base64_u32(body.triangles),
        "joints": base64_u32(body.joints),
        "weights": base64_f32(body.weights),
        "owners": base64_u32(body.owners),
        "bind": base64_f32(bind / metre),
    }


def mannequin_levels(request: object) -> dict:
    """The reply to a live page's ``{"skeleton": <a stream header's skeleton>, "frame": [first
    decoded frame's channels]}``: the mannequin at every level of detail (nearest first);
    MocodecError naming what is wrong with the request."""
    try:
        if not isinstance(request, dict):
            raise TypeError("not an object")
        skeleton = skeleton_from_dict(request["skeleton"])
        frame = np.asarray(request.get("frame") or np.zeros(skeleton.num_channels), dtype=np.float64)
        if frame.shape != (skeleton.num_channels,) or not np.isfinite(frame).all():
            raise ValueError(f"frame must be {skeleton.num_channels} finite numbers")
        return {"levels": [body_of(skeleton, frame, level) for level in range(len(mannequin.LEVELS))]}
    except MocodecError:
        raise
    except (KeyError, TypeError, ValueError) as e:
        raise MocodecError(f'expected {{"skeleton": {{...}}, "frame": [...]}}: {e}') from None


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


class ViewSession:
    def __init__(self, motion: Motion, name: str = ""):
        self.motion, self.name = motion, name
        self.positions = motion.positions_m()
        self.quats = orientations(motion)
        self.body = body_of(motion.skeleton, motion.channels[0] if motion.num_frames else None)
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
        self.coded = Coded(codec, trip.decoded, {k: _finite(v) for k, v in numbers.items()}, trip.decoded.positions_m())
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
                decoded_quats=orientations(self.coded.decoded),
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

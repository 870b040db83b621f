"""The JSON the pages receive: arrays as base64 (decoded in the browser with ``atob``), a
motion's joint rotations, and a skeleton's mannequin (:mod:`mocodec.mannequin`) at each level
of detail, for the file viewer, the studies and the live pages of the viewer and the relay."""

from __future__ import annotations

import base64
import json

import numpy as np

from mocodec import mannequin
from mocodec.errors import MocodecError
from mocodec.formats.container import skeleton_from_dict
from mocodec.kinematics import forward_kinematics
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


def body_or_none(skeleton: Skeleton, first_frame: np.ndarray | None = None) -> dict | None:
    """:func:`body_of`, or None for a skeleton without a bone to build on (a page then draws
    stick figures)."""
    try:
        return body_of(skeleton, first_frame)
    except ValueError:
        return None


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


class Mannequins:
    """The mannequins a server made for live pages, by request text (:func:`mannequin_levels`),
    the ``kept`` newest: avatars of one kind send one request, so each kind is made once."""

    def __init__(self, kept: int):
        self.kept = kept
        self.made: dict[str, dict] = {}

    def __contains__(self, request: str) -> bool:
        return request in self.made

    def __getitem__(self, request: str) -> dict:
        return self.made[request]

    def make(self, request: str) -> dict:
        """The reply to ``request`` (JSON text), kept; MocodecError in one line where it is not
        such a request."""
        try:
            doc = json.loads(request)
        except (ValueError, RecursionError) as e:
            raise MocodecError(f"not JSON: {e}") from None
        self.made[request] = reply = mannequin_levels(doc)
        while len(self.made) > self.kept:
            self.made.pop(next(iter(self.made)))
        return reply

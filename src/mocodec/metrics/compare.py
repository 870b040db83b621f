"""``compare``: every measure of an original motion against its decoded version, at once.

The decoded angles are first expressed as the equivalent Euler triples nearest the original's
(:meth:`Motion.aligned_to`): a coder that returns (a+180, 180-b, c+180) for (a, b, c) has made
no error, and channel-space measures (PSNR, VPSNR, group errors) must not say otherwise.

Forward kinematics runs once per motion and feeds the joint, shell, foot, jerk and group
position measures. The result prints as a table (``table()``) or serialises to plain JSON
types (``as_dict()``); ``per_joint_table()`` lists the errors joint by joint. The decoded
joints are placed by the decoded motion's own skeleton: a lossy .moc file stores offsets rounded
to 0.001 cm, and what it moves counts as error.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mocodec.errors import MocodecError
from mocodec.jsonable import jsonable
from mocodec.kinematics import forward_kinematics
from mocodec.metrics import groups as grp
from mocodec.metrics.natural import Naturalness, naturalness
from mocodec.metrics.pose import (
    SHELL_CM,
    FootSliding,
    Jerk,
    JointErrors,
    bone_joints,
    foot_sliding,
    jerk,
    joint_errors,
    shell_errors,
)
from mocodec.metrics.visual import VisualErrors, visual_errors
from mocodec.metrics.waveform import DofErrors, channel_error, errors_of
from mocodec.motion import Motion

SKELETON_TOLERANCE_CM = 0.001  # offsets closer than this are the same skeleton (a lossy file rounds them)


class MismatchError(MocodecError):
    """The two motions cannot be compared (different skeletons, frame counts or rates)."""


def check_pair(original: Motion, decoded: Motion) -> None:
    """Raise :class:`MismatchError` with one line unless the pair is comparable."""
    sk = original.skeleton
    d = sk.difference(
        decoded.skeleton, atol=max(1e-4, SKELETON_TOLERANCE_CM * sk.units_per_metre / 100.0), end_site_names=False
    )
    if d:
        raise MismatchError(f"different skeletons: {d}")
    if not np.isclose(original.fps, decoded.fps, rtol=1e-6):
        raise MismatchError(f"different frame rates: {original.fps:g} vs {decoded.fps:g} fps")
    if original.num_frames != decoded.num_frames:
        raise MismatchError(f"different frame counts: {original.num_frames} vs {decoded.num_frames}")
    if original.num_frames == 0:
        raise MismatchError("no frames to compare")
    if not np.isfinite(decoded.channels).all():
        raise MismatchError("the decoded motion holds NaN or infinite values")


@dataclass(frozen=True)
class Comparison:
    """All measures of one original/decoded pair (see :func:`compare`)."""

    original: Motion
    decoded: Motion
    dof: DofErrors
    visual: VisualErrors
    joints: JointErrors  # cm, every pivot
    shell: JointErrors  # cm, bone joints (see pose.bone_joints)
    feet: FootSliding | None
    jerk: Jerk
    natural: Naturalness
    vector: grp.GroupSeries  # (6-9)
    vector_max: grp.GroupSeries  # (6-10)
    position: grp.GroupSeries  # (6-12), m^2
    configuration: grp.GroupSeries  # (6-14)
    shell_cm: float = SHELL_CM

    def summary(self) -> dict[str, float | int | None]:
        """The headline numbers, flat."""
        sk = self.original.skeleton
        rot = sk.rotation_mask
        return {
            "frames": self.original.num_frames,
            "fps": self.original.fps,
            "channels": sk.num_channels,
            "constant_dofs": int(self.dof.constant.sum()),
            "exact_dofs": int(self.dof.exact.sum()),
            "psnr_db": self.dof.body_psnr,
            "pooled_psnr_db": self.dof.pooled_psnr,
            "nsnr_db": self.dof.body_nsnr,
            "vpsnr_db": self.visual.body_vpsnr,
            "vmse": self.visual.body_vmse,
            "rotation_rmse_deg": float(np.sqrt(self.dof.mse[rot].mean())) if rot.any() else 0.0,
            "rotation_max_deg": float(self.dof.max_abs[rot].max()) if rot.any() else 0.0,
            "translation_rmse_cm": float(np.sqrt(self.dof.mse[~rot].mean())) * 100 / sk.units_per_metre
            if (~rot).any()
            else 0.0,
            "mean_joint_error_cm": self.joints.mean,
            "max_joint_error_cm": self.joints.max,
            "mean_shell_error_cm": self.shell.mean,
            "max_shell_error_cm": self.shell.max,
            "foot_contact_fraction": self.feet.contact_fraction if self.feet else None,
            "foot_slide_original_cm_s": self.feet.original_cm_s if self.feet else None,
            "foot_slide_decoded_cm_s": self.feet.decoded_cm_s if self.feet else None,
            "jerk_original_m_s3": self.jerk.original_m_s3,
            "jerk_decoded_m_s3": self.jerk.decoded_m_s3,
            "jerk_ratio": self.jerk.ratio,
            "limit_violations": self.natural.limit_violations,
            "original_limit_violations": self.natural.original_limit_violations,
            "velocity_outliers": self.natural.velocity_outliers,
            "acceleration_outliers": self.natural.acceleration_outliers,
        }

    def as_dict(self, per_joint: bool = False) -> dict:
        """Plain JSON-ready data: the summary, group measures and (optionally) per-joint and
        per-DOF figures. Infinite or undefined numbers become None."""
        out = {
            "summary": jsonable(self.summary()),
            "groups": {
                "vector_error_6_9": jsonable(self.vector.as_dict()),
                "max_vector_error_6_10": jsonable(self.vector_max.as_dict()),
                "joint_position_error_6_12_m2": jsonable(self.position.as_dict()),
                "configuration_error_6_14": jsonable(self.configuration.as_dict()),
            },
        }
        if per_joint:
            out["joints"] = jsonable(self.per_joint())
            out["dofs"] = jsonable(self.per_dof())
        return out

    def per_joint(self) -> list[dict]:
        sk = self.original.skeleton
        shell = dict(zip(bone_joints(sk).tolist(), zip(self.shell.joint_mean, self.shell.joint_max)))
        rows = []
        for i, name in enumerate(sk.names):
            s = shell.get(i, (None, None))
            rows.append(
                {
                    "joint": name,
                    "part": sk.body_parts[i],
                    "mean_cm": float(self.joints.joint_mean[i]),
                    "max_cm": float(self.joints.joint_max[i]),
                    "shell_mean_cm": None if s[0] is None else float(s[0]),
                    "shell_max_cm": None if s[1] is None else float(s[1]),
                }
            )
        return rows

    def per_dof(self) -> list[dict]:
        sk = self.original.skeleton
        return [
            {
                "dof": name,
                "range": float(self.dof.range[c]),
                "rmse": float(self.dof.rmse[c]),
                "max_abs": float(self.dof.max_abs[c]),
                "psnr_db": float(self.dof.psnr[c]),
                "vpsnr_db": float(self.visual.vpsnr[c]),
            }
            for c, name in enumerate(sk.channel_names)
        ]

    def table(self) -> str:
        """The summary as an aligned two-column table."""
        s = self.summary()
        rows = [
            (
                "frames",
                f"{s['frames']} at {s['fps']:g} fps, {s['channels']} channels "
                f"({s['constant_dofs']} constant, {s['exact_dofs']} exact)",
            ),
            ("PSNR (mean over DOFs)", db_text(s["psnr_db"])),
            ("PSNR (pooled)", db_text(s["pooled_psnr_db"])),
            ("NSNR (mean over DOFs)", db_text(s["nsnr_db"])),
            ("VPSNR (mean over DOFs)", db_text(s["vpsnr_db"])),
            ("rotation RMSE / max", f"{s['rotation_rmse_deg']:.4g} / {s['rotation_max_deg']:.4g} deg"),
            ("root translation RMSE", f"{s['translation_rmse_cm']:.4g} cm"),
            ("joint error mean / max", f"{s['mean_joint_error_cm']:.4g} / {s['max_joint_error_cm']:.4g} cm"),
            (
                f"shell error ({self.shell_cm:g} cm) mean / max",
                f"{s['mean_shell_error_cm']:.4g} / {s['max_shell_error_cm']:.4g} cm",
            ),
        ]
        if self.feet is not None:
            rows.append(
                (
                    "foot sliding orig / decoded",
                    f"{s['foot_slide_original_cm_s']:.3g} / {s['foot_slide_decoded_cm_s']:.3g} cm/s "
                    f"({100 * float(s['foot_contact_fraction'] or 0.0):.0f}% of foot samples planted)",
                )
            )
        rows += [
            (
                "RMS jerk orig / decoded",
                f"{s['jerk_original_m_s3']:.4g} / {s['jerk_decoded_m_s3']:.4g} m/s^3 (x{s['jerk_ratio']:.3g})",
            ),
            ("joint-limit violations", f"{s['limit_violations']} (original {s['original_limit_violations']})"),
            ("derivative outliers", f"{s['velocity_outliers']} velocity, {s['acceleration_outliers']} acceleration"),
        ]
        lines = [f"{k:<32}{v}" for k, v in rows]
        lines.append("")
        lines.append(f"{'group':<12}{'w (6-9)':>11}{'m max (6-10)':>14}{'p (6-12) m2':>14}{'c (6-14)':>11}")
        for g, w, m, p, c in zip(
            self.vector.groups,
            self.vector.mean,
            self.vector_max.max,
            _by_group(self.position, self.vector.groups),
            _by_group(self.configuration, self.vector.groups),
        ):
            lines.append(f"{g:<12}{w:>11.3g}{m:>14.3g}{_fmt(p):>14}{_fmt(c):>11}")
        return "\n".join(lines)

    def per_joint_table(self) -> str:
        lines = [f"{'joint':<22}{'part':<12}{'mean cm':>9}{'max cm':>9}{'shell max':>11}"]
        for r in self.per_joint():
            shell = "" if r["shell_max_cm"] is None else f"{r['shell_max_cm']:.3f}"
            lines.append(f"{r['joint']:<22}{r['part']:<12}{r['mean_cm']:>9.3f}{r['max_cm']:>9.3f}{shell:>11}")
        return "\n".join(lines)


def _by_group(series: grp.GroupSeries, groups=None) -> list[float | None]:
    means = dict(zip(series.groups, series.mean))
    return [means.get(g) for g in (groups or series.groups)]


def _fmt(x) -> str:
    return "-" if x is None else f"{x:.3g}"


def db_text(x: float | int | None) -> str:
    """A decibel figure for tables: "lossless" for +inf, "n/a" for none."""
    if x is None:
        return "n/a"
    return f"{x:.2f} dB" if np.isfinite(x) else ("lossless" if x > 0 else "n/a")


def compare(original: Motion, decoded: Motion, weights=None, ranges=None, shell_cm: float = SHELL_CM) -> Comparison:
    """Every measure of ``decoded`` against ``original``. ``weights`` and ``ranges`` are the
    a and b of the group measures (6-9), (6-10), (6-14) (see :mod:`mocodec.metrics.groups`)."""
    check_pair(original, decoded)
    decoded = decoded.aligned_to(original)  # equivalent Euler triples are not errors
    sk = original.skeleton
    err = channel_error(original.channels, decoded.channels, sk.rotation_mask)
    dof = errors_of(original.channels, err)
    to_cm = 100.0 / sk.units_per_metre
    pos, quat = forward_kinematics(sk, original.channels)
    dpos, dquat = forward_kinematics(decoded.skeleton, decoded.channels)  # its offsets may be rounded
    pos *= to_cm
    dpos *= to_cm
    rel = grp.relative_positions(sk, pos / 100.0, quat)
    drel = grp.relative_positions(sk, dpos / 100.0, dquat)
    return Comparison(
        original=original,
        decoded=decoded,
        dof=dof,
        visual=visual_errors(err, dof.range, original.fps),
        joints=joint_errors(pos, dpos),
        shell=shell_errors(sk, pos, quat, dpos, dquat, shell_cm),
        feet=foot_sliding(sk, pos, dpos, original.fps),
        jerk=jerk(pos, dpos, original.fps),
        natural=naturalness(sk, original.channels, decoded.channels),
        vector=grp.vector_error(sk, original.channels, err, weights, ranges),
        vector_max=grp.max_vector_error(sk, original.channels, err, weights, ranges),
        position=grp.joint_position_error(sk, pos / 100.0, dpos / 100.0),
        configuration=grp.configuration_error(sk, original.channels, err, rel, drel, weights, ranges),
        shell_cm=shell_cm,
    )

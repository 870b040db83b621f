"""``analyze``: the data analysis of 000 ch. 5 for one motion, as plain numbers (JSON-ready)
and a printable summary. Plots are drawn by :mod:`mocodec.analysis.plots`."""

from __future__ import annotations

import numpy as np

from mocodec.analysis import density, spectrum, stats, temporal
from mocodec.errors import MocodecError
from mocodec.jsonable import jsonable
from mocodec.motion import Motion
from mocodec.skeleton import BODY_PARTS

DEFAULT_NOISE_DEG = 0.1  # assumed sensor noise (standard deviation) for table 5-4
DEFAULT_NOISE_CM = 0.1
CONSTANT = 1e-6
MIN_FRAMES = 2 * spectrum.AR_ORDER  # shorter, the AR spectrum and the fits have nothing to stand on


def group_dofs(motion: Motion) -> dict[str, np.ndarray]:
    """Varying rotation DOFs of every body part (the groups of Table 5-1), in its order."""
    sk = motion.skeleton
    parts = np.array(sk.body_parts)[sk.channel_joints]
    varying = (np.ptp(motion.channels, axis=0) > CONSTANT) & sk.rotation_mask
    out = {}
    for part in BODY_PARTS:
        idx = np.flatnonzero((parts == part) & varying)
        if idx.size:
            out[part] = idx
    return out


def representative_dof(motion: Motion, idx: np.ndarray) -> int:
    """The DOF of a group with the largest standard deviation: the one the figures show."""
    return int(idx[np.argmax(motion.channels[:, idx].std(axis=0))])


def _nanmedian(values: np.ndarray) -> float:
    values = values[np.isfinite(values)]
    return float(np.median(values)) if values.size else float("nan")


def analyze(motion: Motion, noise_deg: float = DEFAULT_NOISE_DEG, noise_cm: float = DEFAULT_NOISE_CM) -> dict:
    """Every number of the chapter-5 analysis, per DOF and per group; MocodecError on a clip
    shorter than MIN_FRAMES (its spectra and fits have nothing to stand on)."""
    if motion.num_frames < MIN_FRAMES:
        raise MocodecError(
            f"the analysis needs at least {MIN_FRAMES} frames (its AR spectrum is of order {spectrum.AR_ORDER}); "
            f"the clip has {motion.num_frames}"
        )
    sk, fps = motion.skeleton, motion.fps
    st = stats.dof_statistics(motion)
    bits = stats.resolution_bits(motion, noise_deg, noise_cm)
    varying = st.range > CONSTANT
    groups = {}
    for part, idx in group_dofs(motion).items():
        x = motion.channels[:, idx]
        welch = spectrum.welch(x, fps)
        bt = spectrum.blackman_tukey(x, fps)
        ar = spectrum.ar_spectrum(x, fps)
        acfs = temporal.autocorrelation(x, max(10, int(fps)))
        fits = [temporal.markov_fit(acfs[:, k], max_lag=max(10, int(round(10 * fps / 30)))) for k in range(len(idx))]
        decay30 = [f.decay_at(fps) for f in fits if np.isfinite(f.decay)]
        wss = temporal.stationarity(x, fps, max_lag_s=1 / 3)
        shape = density.laplace_or_gauss(density.first_difference(x))
        groups[part] = {
            "dofs": len(idx),
            "representative_dof": sk.channel_names[representative_dof(motion, idx)],
            "power_99_hz": spectrum.power_frequency(welch, 0.99),
            "cutoff_40db_hz": spectrum.cutoff_frequency(welch, 40),
            "cutoff_50db_hz": spectrum.cutoff_frequency(welch, 50),
            "cutoff_50db_hz_blackman_tukey": spectrum.cutoff_frequency(bt, 50),
            "cutoff_50db_hz_ar": spectrum.cutoff_frequency(ar, 50),
            "markov_decay_30hz_median": float(np.median(decay30)) if decay30 else None,
            "mean_drift_median": _nanmedian(wss.mean_drift),
            "acf_spread_median": _nanmedian(wss.acf_spread),
            "difference_shape": shape.best,
            "difference_excess_kurtosis": shape.excess_kurtosis,
            "difference_std_deg": float(density.first_difference(x).std()),
        }
    return jsonable(
        {
            "frames": motion.num_frames,
            "fps": fps,
            "duration_s": motion.duration,
            "channels": sk.num_channels,
            "varying_channels": int(varying.sum()),
            "raw_bitrate_32bit": motion.raw_bitrate,
            "noise_deg": noise_deg,
            "noise_cm": noise_cm,
            "usable_bits_per_frame": int(bits[varying].sum()),
            "usable_bitrate": stats.raw_bit_rate(bits[varying], fps),
            "groups": groups,
            "dofs": [
                {
                    "dof": name,
                    "min": float(st.minimum[c]),
                    "max": float(st.maximum[c]),
                    "range": float(st.range[c]),
                    "mean": float(st.mean[c]),
                    "std": float(st.std[c]),
                    "usable_bits": int(bits[c]) if varying[c] else 0,
                }
                for c, name in enumerate(st.names)
            ],
        }
    )


def summary_text(result: dict, path: str) -> str:
    """The printed summary of :func:`analyze`."""
    lines = [
        f"file         {path}",
        f"frames       {result['frames']} at {result['fps']:g} fps = {result['duration_s']:.1f} s; "
        f"{result['varying_channels']} of {result['channels']} channels vary",
        f"raw rate     {result['raw_bitrate_32bit'] / 1000:.1f} kbit/s at 32-bit floats; "
        f"{result['usable_bitrate'] / 1000:.1f} kbit/s at the usable resolution "
        f"({result['usable_bits_per_frame']} bits/frame; noise {result['noise_deg']:g} deg, {result['noise_cm']:g} cm)",
        "",
        f"{'group':<12}{'DOFs':>5}{'99% power':>11}{'-40 dB':>9}{'-50 dB':>9}{'50 dB BT':>10}{'50 dB AR':>10}"
        f"{'Markov a':>11}{'drift':>7}{'diff PDF':>10}",
    ]
    for part, g in result["groups"].items():
        a = g["markov_decay_30hz_median"]
        lines.append(
            f"{part:<12}{g['dofs']:>5}{g['power_99_hz']:>9.2f}Hz{g['cutoff_40db_hz']:>7.2f}Hz{g['cutoff_50db_hz']:>7.2f}Hz"
            f"{g['cutoff_50db_hz_blackman_tukey']:>8.2f}Hz{g['cutoff_50db_hz_ar']:>8.2f}Hz"
            f"{'-' if a is None else f'{a:.2g}':>11}{g['mean_drift_median']:>7.2f}{g['difference_shape']:>10}"
        )
    lines.append("")
    lines.append(
        "Markov a is the decay of phi(m) = A exp(-a m^2) at 30 Hz lags (thesis: 2.5e-4 conversation, 0.015 dance);"
    )
    lines.append("drift is the spread of the means of 10 s windows (a third of a shorter clip) over the DOF's")
    lines.append("standard deviation (small = stationary).")
    return "\n".join(lines)

"""PNG figures of the chapter-5 analysis (matplotlib, Agg backend), in the style of the
thesis's figures 5-3 to 5-12. Needs the ``plot`` extra: ``pip install 'mocodec[plot]'``."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from mocodec.analysis import density, spectrum, temporal
from mocodec.analysis.report import group_dofs, representative_dof
from mocodec.extras import require
from mocodec.motion import Motion


def _pyplot():
    matplotlib = require("matplotlib", "plot", "plotting")
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _save(fig, path: Path) -> Path:
    tmp = path.with_name(path.name + ".tmp")
    fig.savefig(tmp, dpi=110, bbox_inches="tight", format="png")
    tmp.replace(path)
    return path


def write_plots(motion: Motion, out_dir: str | Path) -> list[Path]:
    """Draw every figure of the analysis into ``out_dir``; return the files written."""
    plt = _pyplot()
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    fps, names = motion.fps, motion.skeleton.channel_names
    groups = group_dofs(motion)
    written = []

    fig, ax = plt.subplots(figsize=(7, 4.5))
    for part, idx in groups.items():
        s = spectrum.welch(motion.channels[:, idx], fps)
        ax.semilogx(s.freqs[1:], s.db()[1:], label=part)
    for level in (40, 50):
        ax.axhline(-level, color="grey", lw=0.8, ls="--")
    ax.set(xlabel="f [Hz]", ylabel="PSD [dB re peak]", title="Long-term PSD per group (fig. 5-12)", ylim=(-90, 5))
    ax.legend(fontsize=8)
    written.append(_save(fig, out / "psd.png"))
    plt.close(fig)

    fig, axes = plt.subplots(2, 1, figsize=(7, 7))
    for part, idx in groups.items():
        rep = representative_dof(motion, idx)
        d = density.pdf(motion.channels[:, rep], bins=60)
        axes[0].plot(d.centres, d.density, label=names[rep])
        diff = density.pdf(density.first_difference(motion.channels[:, idx]), bins=80)
        axes[1].semilogy(diff.centres, np.where(diff.density > 0, diff.density, np.nan), label=part)
    axes[0].set(xlabel="angle [deg]", ylabel="density", title="PDF of each group's most varied DOF (fig. 5-6)")
    axes[1].set(
        xlabel="first difference [deg/frame]", ylabel="density", title="First-difference PDF per group (fig. 5-7)"
    )
    for ax in axes:
        ax.legend(fontsize=7)
    fig.tight_layout()
    written.append(_save(fig, out / "pdf.png"))
    plt.close(fig)

    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    part = "left_arm" if "left_arm" in groups else next(iter(groups))
    rep = representative_dof(motion, groups[part])
    wss = temporal.stationarity(motion.channels[:, rep], fps)
    lags = np.arange(wss.acfs.shape[1]) / fps
    for origin, acf in zip(wss.origins_s, wss.acfs[:, :, 0]):
        axes[0].plot(lags, acf, lw=0.9, label=f"origin {origin:.0f} s")
    acf = temporal.autocorrelation(motion.channels[:, rep], wss.acfs.shape[1] - 1)[:, 0]
    fit = temporal.markov_fit(acf, max_lag=max(10, int(round(10 * fps / 30))))
    axes[0].plot(lags, fit.model(np.arange(len(lags))), "k--", label=f"A exp(-a m^2), a={fit.decay_at(fps):.2g} @30 Hz")
    axes[0].set(xlabel="lag [s]", ylabel="autocorrelation", title=f"{names[rep]} (fig. 5-4, 5-5)")
    axes[0].legend(fontsize=7)
    for idx in groups.values():
        r = representative_dof(motion, idx)
        windows = temporal.stationarity(motion.channels[:, r], fps)
        axes[1].plot(windows.origins_s, windows.means[:, 0], marker="o", label=names[r])
    window_s = min(10.0, motion.duration / 3)
    axes[1].set(xlabel="window origin [s]", ylabel="mean [deg]", title=f"Mean over {window_s:.3g} s windows (fig. 5-3)")
    axes[1].legend(fontsize=7)
    fig.tight_layout()
    written.append(_save(fig, out / "stationarity.png"))
    plt.close(fig)

    idx = groups[part]
    if len(idx) >= 2:
        order = idx[np.argsort(motion.channels[:, idx].std(axis=0))[::-1]]
        a, b = order[0], order[1]
        dens, xe, ye = density.joint_pdf(motion.channels[:, a], motion.channels[:, b])
        fig, ax = plt.subplots(figsize=(5, 5))
        ax.imshow(dens.T, origin="lower", extent=(xe[0], xe[-1], ye[0], ye[-1]), cmap="Greys", aspect="auto")
        ax.set(xlabel=names[a], ylabel=names[b], title="Joint PDF of a DOF pair (fig. 5-9)")
        written.append(_save(fig, out / "joint_pdf.png"))
        plt.close(fig)
    return written

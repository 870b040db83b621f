"""Redraw fig. 6-2 of 000 (PSNR vs VPSNR for simulated errors) on a real CMU DOF.

Amplitude errors: the DOF quantised to 2^r levels over its range. Phase errors: the DOF
delayed by 0.5 s / r. As in the thesis the "rate" r is a dimensionless knob (1..10). Writes
docs/figures/fig_6_2_psnr_vs_vpsnr.png and prints the numbers.
Run: `.venv/bin/python benchmarks/fig_6_2_vmse.py`.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from common import options  # noqa: E402
from mocodec import load  # noqa: E402
from mocodec.metrics import dof_errors, visual_errors  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
DOF = "lhumerus.Xrotation"


def measure(x: np.ndarray, y: np.ndarray, fps: float) -> tuple[float, float]:
    dof = dof_errors(x[:, None], y[:, None])
    vis = visual_errors(y[:, None] - x[:, None], dof.range, fps)
    return float(dof.psnr[0]), float(vis.vpsnr[0])


def main() -> None:
    options(__doc__)
    motion = load(ROOT / "tests" / "data" / "135_08.amc")
    x = motion.channels[:, motion.skeleton.channel_index(DOF)]
    fps = motion.fps
    lo, span = x.min(), np.ptp(x)
    rates = np.arange(1, 11)
    rows = []
    for r in rates:
        step = span / (2**r - 1)
        quantised = lo + np.round((x - lo) / step) * step
        shift = int(round(0.5 * fps / r))
        keep = slice(shift, len(x))
        rows.append((r, *measure(x, quantised, fps), shift, *measure(x[keep], np.roll(x, shift)[keep], fps)))
    print(f"{DOF} of CMU 135_08 ({len(x)} frames at {fps:g} fps)")
    print(f"{'r':>3}{'quant PSNR':>12}{'VPSNR':>8}{'shift':>7}{'phase PSNR':>12}{'VPSNR':>8}")
    for r, qp, qv, s, pp, pv in rows:
        print(f"{r:>3}{qp:>12.1f}{qv:>8.1f}{s:>7}{pp:>12.1f}{pv:>8.1f}")
    data = np.array([(r, qp, qv, pp, pv) for r, qp, qv, _, pp, pv in rows])
    fig, ax = plt.subplots(figsize=(7, 4.5))
    ax.plot(data[:, 0], data[:, 1], "o-", label="PSNR, amplitude (quantisation) errors")
    ax.plot(data[:, 0], data[:, 2], "s-", label="VPSNR, amplitude errors")
    ax.plot(data[:, 0], data[:, 3], "^--", label="PSNR, phase (time-shift) errors")
    ax.plot(data[:, 0], data[:, 4], "d--", label="VPSNR, phase errors")
    ax.set(xlabel="rate r (2^r levels; shift 0.5 s / r)", ylabel="dB", title=f"PSNR vs VPSNR (000 fig. 6-2), {DOF}")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    out = ROOT / "docs" / "figures" / "fig_6_2_psnr_vs_vpsnr.png"
    fig.savefig(out, dpi=100, bbox_inches="tight")
    print(f"wrote {out.relative_to(ROOT)}")


if __name__ == "__main__":
    main()

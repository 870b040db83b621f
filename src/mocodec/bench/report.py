"""The benchmark report: ``report.html`` (opens offline: plain HTML, PNG plots beside it) and
``report.md`` from the rows of a run.

Rate-distortion curves are medians over clips at each knob setting (per clip charts too); the
summary takes the error-target points: at each max joint error level, the codec whose files are
smallest (median ratio over the clips where every codec compared got there) and how many times
smaller they are than SZ3's and zstandard's (median over clips of the per-clip size ratio).
"""

from __future__ import annotations

import html
import math
from collections import defaultdict
from pathlib import Path
from statistics import median
from typing import Any

from mocodec.bench import published
from mocodec.formats.fileio import atomic_write

LOSSLESS_BASELINE = "zstd"
ERROR_BASELINE = "sz3"


def _ok(rows):
    return [r for r in rows if r["status"] == "ok"]


def curves(rows) -> dict[str, list[dict]]:
    """codec -> the median over clips of every measure at each knob setting, by bit rate (at
    each rate-control target instead for a run without knob sweeps)."""
    groups = defaultdict(list)
    for r in _ok(rows):
        setting = r["knob_value"] if r["point"] == "knob" else r["target"]
        groups[(r["codec"], r["point"], setting)].append(r)
    swept = {codec for codec, point, _ in groups if point == "knob"}
    out = defaultdict(list)
    for (codec, point, setting), rs in groups.items():
        if (point == "knob") != (codec in swept):
            continue
        entry = {
            "knob_value": rs[0]["knob_value"] if point == "knob" else None,
            "point": point,
            "setting": setting,
            "clips": len(rs),
        }
        for k in (
            "ratio",
            "bitrate",
            "bits_per_dof_sample",
            "psnr_db",
            "vpsnr_db",
            "mean_joint_error_cm",
            "max_joint_error_cm",
            "max_shell_error_cm",
            "encode_us_per_frame",
            "decode_us_per_frame",
        ):
            values = [r[k] for r in rs if r.get(k) is not None]
            entry[k] = median(values) if values else None
        out[codec].append(entry)
    return {c: sorted(ps, key=lambda p: p["bitrate"]) for c, ps in sorted(out.items())}


def error_summary(rows) -> list[dict]:
    """Per max-joint-error target: every codec's median ratio and reach, the best codec, and the
    best codec's size advantage over SZ3 and zstandard."""
    clips = sorted({r["clip"] for r in rows})
    lossless = {r["clip"]: r["bytes"] for r in _ok(rows) if r["codec"] == LOSSLESS_BASELINE}
    by_level: defaultdict[float, defaultdict[str, dict]] = defaultdict(lambda: defaultdict(dict))
    for r in _ok(rows):
        if r["point"] == "error":
            by_level[r["target"]][r["codec"]][r["clip"]] = r
    table = []
    for level in sorted(by_level):
        codecs = by_level[level]
        complete = {c: v for c, v in codecs.items() if len(v) == len(clips)}
        entry: dict[str, Any] = {
            "level_cm": level,
            "clips": len(clips),
            "codecs": {
                c: {"reached": len(v), "median_ratio": median(r["ratio"] for r in v.values())}
                for c, v in sorted(codecs.items())
            },
        }
        if complete:
            best = max(complete, key=lambda c: entry["codecs"][c]["median_ratio"])
            entry["best"] = best
            entry["best_ratio"] = entry["codecs"][best]["median_ratio"]
            for name, sizes in (
                (ERROR_BASELINE, {k: r["bytes"] for k, r in codecs.get(ERROR_BASELINE, {}).items()}),
                (LOSSLESS_BASELINE, lossless),
            ):
                factors = [sizes[k] / complete[best][k]["bytes"] for k in clips if k in sizes]
                entry[f"vs_{name}"] = median(factors) if factors else None
        table.append(entry)
    return table


def speeds(rows) -> dict[str, tuple[float, float]]:
    """codec -> median (encode, decode) microseconds per frame over every measured point."""
    by = defaultdict(list)
    for r in _ok(rows):
        by[r["codec"]].append((r["encode_us_per_frame"], r["decode_us_per_frame"]))
    return {c: (median(e for e, _ in v), median(d for _, d in v)) for c, v in sorted(by.items())}


# ----- plots -----------------------------------------------------------------------------------
def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


MARKERS = "o^vD<>PX*h"


def _style(plt, index: int, codec: str, baselines: set[str]):
    """A colour and marker of its own for each of up to 200 codecs; baselines dashed."""
    return {
        "color": plt.get_cmap("tab20")(index % 20),
        "marker": MARKERS[index // 2 % len(MARKERS)],
        "linestyle": "--" if codec in baselines else "-",
        "markersize": 4,
        "linewidth": 1.2,
    }


def plot_rd(curve_map, baselines, path: Path, title: str) -> None:
    plt = _pyplot()
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.8))
    for ax, key, label in (
        (axes[0], "mean_joint_error_cm", "mean joint error (cm)"),
        (axes[1], "max_joint_error_cm", "max joint error (cm)"),
    ):
        for i, (codec, pts) in enumerate(curve_map.items()):
            pts = [p for p in pts if p[key] and p[key] > 0 and p["bitrate"] > 0]
            if pts:
                ax.plot(
                    [p["bitrate"] for p in pts], [p[key] for p in pts], label=codec, **_style(plt, i, codec, baselines)
                )
        ax.set(xscale="log", yscale="log", xlabel="bit rate (bit/s)", ylabel=label)
        ax.grid(True, which="both", alpha=0.3)
    if axes[1].get_legend_handles_labels()[0]:  # (a run of clips with nothing to measure has no curve)
        axes[1].legend(fontsize=7, ncol=2, loc="best")
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def plot_speed(speed, path: Path) -> None:
    plt = _pyplot()
    codecs = list(speed)
    fig, ax = plt.subplots(figsize=(8, 0.3 * len(codecs) + 1.5))
    y = range(len(codecs))
    ax.barh([i - 0.2 for i in y], [speed[c][0] for c in codecs], height=0.4, label="encode (ours)")
    ax.barh([i + 0.2 for i in y], [speed[c][1] for c in codecs], height=0.4, label="decode (ours)")
    for codec, (enc, dec) in published.SPEED_US.items():
        if codec in codecs:
            i = codecs.index(codec)
            ax.plot(enc, [i - 0.2] * 2, "k|-", markersize=8)
            if dec:
                ax.plot(dec, [i + 0.2] * 2, "k|-", markersize=8)
    ax.plot([], [], "k|-", label="thesis (001 tables 3.4, 5.3, 6.4)")
    ax.set(yticks=list(y), yticklabels=codecs, xscale="log", xlabel="microseconds per frame (median over points)")
    ax.invert_yaxis()
    ax.legend(fontsize=8)
    ax.grid(True, axis="x", which="both", alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def plot_appendix_iii(curve_map, path: Path) -> bool:
    """Our median curves beside Appendix III (000), in bits per DOF-sample against (V)PSNR."""
    shown = [c for c in published.APPENDIX_III if c in curve_map]
    if not shown:
        return False
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(9, 5.5))
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    per_sample = published.APPENDIX_III_FPS * published.APPENDIX_III_DOFS
    for i, codec in enumerate(shown):
        colour = colours[i % len(colours)]
        key = published.APPENDIX_III_MEASURE[codec]
        pts = [p for p in curve_map[codec] if p[key] is not None and math.isfinite(p[key])]
        ax.plot(
            [p["bits_per_dof_sample"] for p in pts],
            [p[key] for p in pts],
            "o-",
            color=colour,
            markersize=3,
            label=f"{codec} (ours)",
        )
        thesis = published.APPENDIX_III[codec]
        ax.plot(
            [r / per_sample for _, r, _ in thesis],
            [q for _, _, q in thesis],
            "x--",
            color=colour,
            markersize=5,
            label=f"{codec} (000 App. III)",
        )
    ax.set(xscale="log", xlabel="bits per DOF-sample", ylabel="PSNR dB (VPSNR for posture, gesture, hybrid)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=6, ncol=3)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return True


# ----- documents -------------------------------------------------------------------------------
def _f(x, digits: int = 3) -> str:
    if x is None:
        return "-"
    if isinstance(x, float) and math.isinf(x):
        return "inf"
    return f"{x:.{digits}g}"


def _source(row: dict) -> str:
    """The row's source (results of runs before the column existed: its format)."""
    return row.get("source") or row["format"]


def source_summaries(rows) -> list[tuple[str, dict]]:
    """:func:`error_summary` of all clips, then of each source's (CMU BVH beside Bandai Namco
    BVH, say) when the run has more than one: ``(label, summary)`` per error level."""
    out = [("all", e) for e in error_summary(rows)]
    sources = sorted({_source(r) for r in rows})
    if len(sources) > 1:
        out += [(f, e) for f in sources for e in error_summary([r for r in rows if _source(r) == f])]
    return out


def _tables(rows, meta) -> list[tuple[str, list[str], list[list[str]], str]]:
    """(title, header, body, note) of every table in the report."""
    out = []
    summary = error_summary(rows)
    if summary:
        body = [
            [
                label,
                _f(e["level_cm"]),
                e.get("best", "none reached it on every clip"),
                _f(e.get("best_ratio")),
                _f(e.get(f"vs_{ERROR_BASELINE}")),
                _f(e.get(f"vs_{LOSSLESS_BASELINE}")),
            ]
            for label, e in source_summaries(rows)
        ]
        out.append(
            (
                "Smallest codec at each max joint error",
                [
                    "clips",
                    "max joint error (cm)",
                    "smallest codec",
                    "its median ratio",
                    "x smaller than SZ3",
                    "x smaller than zstd",
                ],
                body,
                "Error-target points (rate control to the bound, verified on the decoded file); the best codec "
                "is taken among those that reached the bound on every clip; factors are medians over clips of "
                "the per-clip size ratio. Ratios count the whole .moc file, skeleton included.",
            )
        )
        codecs = sorted({c for e in summary for c in e["codecs"]})
        body = [
            [c]
            + [
                (
                    f"{_f(e['codecs'][c]['median_ratio'])} ({e['codecs'][c]['reached']}/{e['clips']})"
                    if c in e["codecs"]
                    else "-"
                )
                for e in summary
            ]
            for c in codecs
        ]
        out.append(
            (
                "Median ratio at each max joint error (clips that reached it)",
                ["codec"] + [f"{_f(e['level_cm'])} cm" for e in summary],
                body,
                "",
            )
        )
    curve_map = curves(rows)
    body = [
        [
            c,
            f"{p['point']} {_f(p['setting'])}",
            _f(p["ratio"]),
            _f(p["bitrate"], 4),
            _f(p["bits_per_dof_sample"]),
            _f(p["psnr_db"]),
            _f(p["vpsnr_db"]),
            _f(p["mean_joint_error_cm"]),
            _f(p["max_joint_error_cm"]),
            _f(p["max_shell_error_cm"]),
        ]
        for c, ps in curve_map.items()
        for p in ps
    ]
    out.append(
        (
            "Rate-distortion: medians over clips at each knob setting (or target)",
            [
                "codec",
                "point",
                "ratio",
                "bit/s",
                "bits/DOF-sample",
                "PSNR dB",
                "VPSNR dB",
                "mean cm",
                "max cm",
                "max shell cm",
            ],
            body,
            "",
        )
    )
    body = [[c, _f(e), _f(d)] for c, (e, d) in speeds(rows).items()]
    out.append(
        (
            "Speed (median microseconds per frame, whole file encode and decode, one core per task)",
            ["codec", "encode", "decode"],
            body,
            "",
        )
    )
    out += _published_tables(rows)
    failed = [r for r in rows if r["status"] == "failed"]
    if failed:
        out.append(
            (
                "Failures",
                ["clip", "codec", "point", "message"],
                [
                    [r["clip"], r["codec"], f"{r['point']} {_f(r['target'] or r['knob_value'])}", r["message"]]
                    for r in failed
                ],
                "",
            )
        )
    return out


def _published_tables(rows) -> list:
    ok = _ok(rows)
    out = []
    prim = defaultdict(list)
    for r in ok:
        if (
            r["codec"] == "primitives"
            and r["point"] == "knob"
            and r["knob_value"] is not None
            and abs(r["knob_value"] - published.TABLE_5_1_KNOB) < 1e-9
        ):
            prim[Path(r["clip"]).stem].append(r)
    body = [
        [
            clip,
            f"{ratio}:1",
            " / ".join(f"{_f(r['ratio'])} ({r['format']})" for r in prim[clip]) or "not in this run",
            " / ".join(_f(r["mean_joint_error_cm"]) for r in prim[clip]) or "-",
        ]
        for clip, ratio in published.TABLE_5_1.items()
    ]
    out.append(
        (
            "001 table 5.1: primitives at t_L = 0.01",
            ["clip", "thesis ratio", "our ratio", "our mean cm"],
            body,
            "The thesis counts the body and keeps its primitive database outside; our files carry everything.",
        )
    )
    pw = defaultdict(list)
    for r in ok:
        if r["codec"] == "pwavelet" and r["point"] == "ratio":
            pw[r["target"]].append(r["mean_joint_error_cm"])
    body = [
        [
            f"{ratio}:1",
            " / ".join(f"{s[ratio]:.2f}" for s in published.TABLE_3_1.values()),
            _f(median(pw[ratio])) if pw.get(ratio) else "run with --points ratio",
        ]
        for ratio in (20, 25, 30, 35, 40)
    ]
    out.append(
        (
            "001 table 3.1: pwavelet",
            ["ratio", "thesis scores 02_02 / 49_14 (1-5)", "our median mean joint cm"],
            body,
            "The thesis measured quality by a user study; we report joint position error.",
        )
    )
    at = published.TABLE_6_2_SPIHT_RATIO
    sp = [r for r in ok if r["codec"] == "spiht" and r["point"] == "ratio" and r["target"] == at]
    ours = (
        f"spiht {at}:1: median mean joint error {_f(median(r['mean_joint_error_cm'] for r in sp))} cm"
        if sp
        else f"spiht at {at}:1: run with --points ratio"
    )
    body = [[name, f"{a}:1", f"{b}:1"] for name, (a, b) in published.TABLE_6_2.items()]
    out.append(("001 table 6.2: ratios reported in the literature", ["method", "average", "best"], body, ours))
    return out


def _html_table(title, header, body, note) -> str:
    head = "".join(f"<th>{html.escape(h)}</th>" for h in header)
    rows = "".join("<tr>" + "".join(f"<td>{html.escape(str(c))}</td>" for c in r) + "</tr>" for r in body)
    note = f"<p class='note'>{html.escape(note)}</p>" if note else ""
    return f"<h2>{html.escape(title)}</h2><table><tr>{head}</tr>{rows}</table>{note}"


def _md_table(title, header, body, note) -> str:
    lines = [f"## {title}", "", "| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(str(c).replace("|", "/") for c in r) + " |" for r in body]
    return "\n".join(lines + ([f"\n{note}"] if note else []) + [""])


CSS = (
    "body{font-family:sans-serif;max-width:1200px;margin:auto;padding:1em}table{border-collapse:collapse;"
    "margin:0.5em 0}td,th{border:1px solid #ccc;padding:2px 6px;font-size:13px;text-align:right}"
    "td:first-child,th:first-child{text-align:left}.note{color:#555;font-size:13px}img{max-width:100%}"
)


def write_report(rows, meta, out_dir) -> list[Path]:
    """``report.html``, ``report.md`` and the PNGs under ``plots/``; returns the paths written."""
    out = Path(out_dir)
    plots = out / "plots"
    plots.mkdir(exist_ok=True)
    baselines = {r["codec"] for r in rows if r.get("baseline")}
    curve_map = curves(rows)
    figures = [("Rate-distortion over every clip (median at each knob setting or target)", "plots/overall.png")]
    plot_rd(curve_map, baselines, plots / "overall.png", f"{meta['clips']} clips, medians per knob setting")
    plot_speed(speeds(rows), plots / "speed.png")
    figures.append(("Speed, with the thesis's figures (another machine: a 2.66 GHz Core 2 Duo)", "plots/speed.png"))
    if plot_appendix_iii(curve_map, plots / "appendix_iii.png"):
        figures.append(
            (
                "Ours beside 000 Appendix III (its own 30 Hz, 52-DOF sequences; ours at the clips' rate, "
                "so per-sample rates favour ours)",
                "plots/appendix_iii.png",
            )
        )
    clip_figures = []
    for clip in sorted({r["clip"] for r in rows}):
        name = "clip_" + "".join(ch if ch.isalnum() else "_" for ch in clip) + ".png"
        clip_rows = [r for r in rows if r["clip"] == clip]
        if _ok(clip_rows):
            plot_rd(curves(clip_rows), baselines, plots / name, clip)
            clip_figures.append((clip, f"plots/{name}"))
    tables = _tables(rows, meta)
    versions = ", ".join(f"{k} {v}" for k, v in meta["versions"].items() if v)
    total = meta.get("wall_s_total", meta["wall_s"])
    facts = [
        f"command: {meta['command']}",
        f"wall time {meta['wall_s']:.0f} s for {meta['tasks_run']} tasks "
        f"({meta['tasks_resumed']} resumed from earlier runs, {total:.0f} s in all), {meta['jobs']} jobs, "
        f"{meta['scheduler']}",
        f"{meta['clips']} clips, codecs: {', '.join(meta['codecs'])}",
        f"machine: {meta['machine']['platform']}, {meta['machine']['cores']} cores, Python {meta['machine']['python']}",
        f"versions: {versions}",
    ]
    page = [
        f"<!doctype html><html><head><meta charset='utf-8'><title>mocodec benchmark</title><style>{CSS}</style>"
        "</head><body><h1>mocodec benchmark</h1><ul>" + "".join(f"<li>{html.escape(f)}</li>" for f in facts) + "</ul>"
    ]
    page += [_html_table(*t) for t in tables[:1]]
    page += [f"<h2>{html.escape(t)}</h2><img src='{src}' alt='{html.escape(t)}'>" for t, src in figures]
    page += [_html_table(*t) for t in tables[1:]]
    page.append(
        "<h2>Per clip</h2>"
        + "".join(
            f"<details><summary>{html.escape(c)}</summary><img src='{src}' alt='{html.escape(c)}'></details>"
            for c, src in clip_figures
        )
    )
    page.append("</body></html>")
    md = ["# mocodec benchmark", ""] + [f"- {f}" for f in facts] + [""]
    md += [_md_table(*t) for t in tables[:1]]
    md += [f"## {t}\n\n![{t}]({src})\n" for t, src in figures]
    md += [_md_table(*t) for t in tables[1:]]
    atomic_write(out / "report.html", "\n".join(page) + "\n")
    atomic_write(out / "report.md", "\n".join(md) + "\n")
    return [out / "report.html", out / "report.md", *(out / s for _, s in figures + clip_figures)]

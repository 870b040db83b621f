"""The benchmark suite: baseline codecs, operating points, the engine (rows, resume, failures),
the local and Dask runners, the report, compress-dir and their commands."""

from __future__ import annotations

import json
import math
import shutil
import sys

import numpy as np
import pytest

from conftest import DATA
from mocodec import moc
from mocodec.bench import compressdir, engine, points, report, runner, suite
from mocodec.cli import main
from mocodec.codecs import codec_class, get_codec
from mocodec.errors import CodecError, MocodecError
from mocodec.ratecontrol import tune

SMALL = DATA / "09_02.bvh"  # 131 frames, 132 channels


# ----- baseline codecs -------------------------------------------------------------------------
def test_zstd_is_exact_at_float32(walk_bvh):
    codec = get_codec("zstd")
    decoded = codec.decode(codec.encode(walk_bvh), walk_bvh.skeleton, walk_bvh.num_frames, walk_bvh.fps)
    expected = walk_bvh.continuous().channels.astype(np.float32).astype(np.float64)
    np.testing.assert_array_equal(decoded.channels, expected)


@pytest.mark.parametrize("codec_id", ["sz3", "zfp"])
@pytest.mark.parametrize("bound", [0.5, 0.01])
def test_error_bounded_baselines_hold_their_bound_per_channel(walk_bvh, codec_id, bound):
    codec = get_codec(codec_id, bound=bound)
    decoded = codec.decode(codec.encode(walk_bvh), walk_bvh.skeleton, walk_bvh.num_frames, walk_bvh.fps)
    sk = walk_bvh.skeleton
    per_channel = np.where(sk.rotation_mask, bound, bound * sk.units_per_metre / 100)
    err = np.abs(decoded.channels - walk_bvh.continuous().channels).max(axis=0)
    assert (err <= per_channel * (1 + 1e-5) + 1e-5).all()


def test_baseline_sizes_fall_as_the_bound_loosens(walk_amc):
    for codec_id, knob, fine, coarse in (
        ("sz3", "bound", 0.001, 0.5),
        ("zfp", "bound", 0.001, 0.5),
        ("fpzip", "precision", 24, 14),
    ):
        sizes = [len(get_codec(codec_id, **{knob: v}).encode(walk_amc)) for v in (fine, coarse)]
        assert sizes[1] < 0.8 * sizes[0], codec_id


def test_fpzip_at_32_bits_is_lossless_at_float32(walk_amc):
    codec = get_codec("fpzip", precision=32)
    decoded = codec.decode(codec.encode(walk_amc), walk_amc.skeleton, walk_amc.num_frames, walk_amc.fps)
    np.testing.assert_array_equal(
        decoded.channels, walk_amc.continuous().channels.astype(np.float32).astype(np.float64)
    )


def test_rate_control_drives_a_baseline_to_a_joint_error_bound(walk_amc):
    m = tune(get_codec("sz3"), walk_amc, "max_error_cm", 0.5)
    assert m.max_error_cm <= 0.5
    assert m.max_error_cm > 0.25  # and does not give away much more than asked


def test_a_missing_baseline_package_is_named(walk_amc, monkeypatch):
    monkeypatch.setitem(sys.modules, "zfpy", None)
    with pytest.raises(CodecError, match="needs the zfpy package"):
        get_codec("zfp").encode(walk_amc)
    assert "zfp" not in suite.default_codecs()


# ----- points ----------------------------------------------------------------------------------
def test_knob_sweeps_run_from_worst_to_best_quality():
    assert points.knob_sweep(codec_class("dpcm")) == [4, 11, 32, 91, 256]  # more levels is better
    assert points.knob_sweep(codec_class("sz3")) == [1.0, 0.1778, 0.03162, 0.005623, 0.001]
    assert points.knob_sweep(codec_class("hybrid")) == [0, 2, 4, 5, 7]  # linear, integers


def test_points_for_a_codec_without_a_knob_is_one_measurement():
    (only,) = points.points_for("lossless", ("knob", "error"))
    assert only.kind == "knob" and math.isnan(only.value)


def test_points_reject_bad_kinds_and_targets():
    with pytest.raises(CodecError, match="unknown kind"):
        points.points_for("dpcm", ("speed",))
    with pytest.raises(CodecError, match="positive"):
        points.points_for("dpcm", ("error",), errors=(0.0,))


# ----- engine and suite ------------------------------------------------------------------------
def test_a_run_measures_every_point_and_meets_error_targets(tmp_path):
    result = suite.run([SMALL], tmp_path, ["kinwave", "sz3", "zstd"], ("knob", "error"), errors=(1.0,), jobs=1)
    rows = result.rows
    assert len(rows) == 2 * (5 + 1) + 1
    assert all(r["status"] == "ok" for r in rows)
    for r in rows:
        assert r["ratio"] == pytest.approx(131 * 132 * 4 / r["bytes"])
        assert r["bits_per_dof_sample"] == pytest.approx(r["bytes"] * 8 / (131 * 132))
        assert r["encode_us_per_frame"] > 0 and r["decode_us_per_frame"] > 0
    for r in rows:
        if r["point"] == "error":
            assert r["max_joint_error_cm"] <= 1.0
    kin = [r for r in rows if r["codec"] == "kinwave" and r["point"] == "knob"]
    assert [r["knob_value"] for r in kin] == [5.0, 1.581, 0.5, 0.1581, 0.05]
    assert all(r["max_joint_error_cm"] <= r["knob_value"] for r in kin)  # kinwave's guarantee
    assert [r["codec"] for r in rows if r["baseline"]] == ["sz3"] * 6 + ["zstd"]
    back = suite.read_rows(tmp_path)
    assert len(back) == len(rows) and back[0]["bytes"] == rows[0]["bytes"]
    meta = json.loads((tmp_path / "meta.json").read_text())
    assert meta["tasks"] == 3 and meta["versions"]["numpy"] and meta["wall_s"] >= 0


def test_a_run_resumes_and_only_runs_what_is_new(tmp_path):
    first = suite.run([SMALL], tmp_path, ["zstd"], report=False, jobs=1)
    again = suite.run([SMALL], tmp_path, ["zstd", "dpcm"], ("knob",), report=False, jobs=1)
    assert again.meta["tasks_resumed"] == 1 and again.meta["tasks_run"] == 1
    assert again.rows[-1]["codec"] == "dpcm" and again.rows[0]["bytes"] == first.rows[0]["bytes"]
    with (tmp_path / "rows.jsonl").open("a") as f:
        f.write('{"task": "cut short')  # an interrupted write
    last = suite.run([SMALL], tmp_path, ["zstd"], report=False, jobs=1).meta
    assert last["tasks_run"] == 0
    assert last["wall_s_total"] == pytest.approx(first.meta["wall_s"] + again.meta["wall_s"] + last["wall_s"], abs=0.2)


def test_a_bad_clip_is_reported_and_the_run_goes_on(tmp_path):
    data = tmp_path / "clips"
    data.mkdir()
    shutil.copy(SMALL, data)
    (data / "broken.bvh").write_text("HIERARCHY\nROOT hip\n{\n")
    result = suite.run([data], tmp_path / "out", ["zstd"], report=False, jobs=1)
    (bad,) = result.failures
    assert bad["clip"] == "broken.bvh" and "broken.bvh" in bad["message"]
    assert [r["status"] for r in result.rows if r["clip"] == "09_02.bvh"] == ["ok"]
    # a failed task is tried again on resume, the good one is not
    assert suite.run([data], tmp_path / "out", ["zstd"], report=False, jobs=1).meta["tasks_run"] == 1


@pytest.mark.parametrize(
    "root, frames, why",
    [
        (" CHANNELS 0", "Frames: 2\nFrame Time: 0.04\n\n\n", "no channels"),
        (" CHANNELS 3 Zrotation Xrotation Yrotation", "Frames: 0\nFrame Time: 0.04\n", "no frames"),
    ],
)
def test_a_clip_without_channels_or_frames_is_skipped(tmp_path, root, frames, why):
    """A rig whose joints never move (no channels: Blender 2.79 writes such files) or a rig
    without a take (no frames) has nothing to measure: one row says so, and the run neither
    fails nor tries it again."""
    still = tmp_path / "still.bvh"
    still.write_text(f"HIERARCHY\nROOT hip\n{{\n OFFSET 0 0 0\n{root}\n}}\nMOTION\n{frames}")
    result = suite.run([still], tmp_path / "out", ["zstd", "kinwave"], report=False, jobs=1)
    assert [(r["codec"], r["status"]) for r in result.rows] == [("zstd", "skipped"), ("kinwave", "skipped")]
    assert why in result.rows[0]["message"] and not result.failures


def test_an_unreachable_target_is_a_row_not_a_failure(tmp_path):
    result = suite.run([SMALL], tmp_path, ["quant"], ("error",), errors=(1e-4,), report=False, jobs=1)
    (row,) = result.rows
    assert row["status"] == "unreachable" and "cannot reach" in row["message"]
    assert not result.failures


def test_find_clips_walks_folders_and_rejects_missing_paths(tmp_path):
    found = dict(engine.find_clips([DATA]))
    assert set(found.values()) == {"07_03.amc", "07_03.bvh", "09_02.bvh", "135_08.amc"}
    with pytest.raises(MocodecError, match="no such file"):
        engine.find_clips([tmp_path / "nothing"])


def _square(x):
    if x == 3:
        raise ValueError("three")
    return x * x


def test_the_process_pool_returns_every_result_and_each_exception():
    results = dict(runner.execute(_square, [1, 2, 3, 4], jobs=2))
    assert results[1] == 1 and results[4] == 16 and isinstance(results[3], ValueError)
    with pytest.raises(MocodecError, match="at least 1"):
        list(runner.execute(_square, [1], jobs=0))


@pytest.mark.slow
def test_a_dask_cluster_runs_the_benchmark(tmp_path):
    distributed = pytest.importorskip("dask.distributed")
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, dashboard_address=None) as cluster:
        result = suite.run(
            [SMALL], tmp_path, ["zstd", "dpcm"], ("knob",), scheduler=cluster.scheduler_address, report=False
        )
    local = suite.run([SMALL], tmp_path / "local", ["zstd", "dpcm"], ("knob",), report=False, jobs=1)
    assert result.meta["scheduler"] == cluster.scheduler_address
    assert [r["bytes"] for r in result.rows] == [r["bytes"] for r in local.rows]  # same bytes anywhere


@pytest.mark.slow
def test_a_local_dask_cluster_runs_compress_dir(tmp_path):
    pytest.importorskip("dask.distributed")
    data = tmp_path / "clips"
    data.mkdir()
    shutil.copy(SMALL, data)
    out = compressdir.compress_dir(data, tmp_path / "out", "dpcm", dask=True, jobs=1)
    assert [r["target"] for r in out.written] == [str(tmp_path / "out" / "09_02.moc")]


# ----- report ----------------------------------------------------------------------------------
def _row(clip, codec, point, target, size, **extra):
    return {
        "clip": clip,
        "codec": codec,
        "point": point,
        "target": target,
        "bytes": size,
        "ratio": 1000 / size,
        "status": "ok",
        "baseline": codec in ("sz3", "zstd"),
        **extra,
    }


def test_error_summary_picks_the_smallest_codec_that_reached_every_clip():
    rows = [
        _row("a", "zstd", "knob", None, 600),
        _row("b", "zstd", "knob", None, 800),
        _row("a", "sz3", "error", 1.0, 200),
        _row("b", "sz3", "error", 1.0, 400),
        _row("a", "kinwave", "error", 1.0, 50),
        _row("b", "kinwave", "error", 1.0, 200),
        _row("a", "dpcm", "error", 1.0, 10),
    ]  # dpcm reached only clip a
    (level,) = report.error_summary(rows)
    assert level["best"] == "kinwave"
    assert level["best_ratio"] == pytest.approx((20 + 5) / 2)
    assert level["vs_sz3"] == pytest.approx((4 + 2) / 2)
    assert level["vs_zstd"] == pytest.approx((12 + 4) / 2)
    assert level["codecs"]["dpcm"]["reached"] == 1


def test_clips_are_grouped_by_source_and_the_report_shows_sources_side_by_side():
    from mocodec.bench.engine import clip_source

    assert clip_source("cmu/bvh/01_01.bvh") == "cmu bvh"
    assert clip_source("bandai/dataset-1_bow_active_001.bvh") == "bandai bvh"
    assert clip_source("walk.amc") == "amc"
    rows = [
        _row(c, codec, "error", 1.0, size, source=clip_source(c), format="bvh")
        for c, codec, size in (
            ("cmu/bvh/a.bvh", "kinwave", 50),
            ("cmu/bvh/a.bvh", "sz3", 200),
            ("bandai/b.bvh", "kinwave", 100),
            ("bandai/b.bvh", "sz3", 300),
        )
    ]
    summaries = report.source_summaries(rows)
    assert [label for label, _ in summaries] == ["all", "bandai bvh", "cmu bvh"]
    assert [e["vs_sz3"] for _, e in summaries] == [3.5, 3.0, 4.0]  # x smaller than SZ3, per source


def test_the_report_shows_every_codec_and_its_plots(tmp_path):
    suite.run([SMALL], tmp_path, ["kinwave", "dpcm", "sz3", "zstd", "fpzip"], ("knob", "error"), errors=(1.0,), jobs=2)
    page = (tmp_path / "report.html").read_text()
    for codec in ("kinwave", "dpcm", "sz3", "zstd", "fpzip"):
        assert f"<td>{codec}</td>" in page
    for src in ("plots/overall.png", "plots/speed.png", "plots/appendix_iii.png"):
        assert f"src='{src}'" in page and (tmp_path / src).stat().st_size > 10_000
    assert "http" not in page.replace("http-equiv", "")  # nothing to fetch: opens offline
    md = (tmp_path / "report.md").read_text()
    assert "| all | 1 | kinwave |" in md


# ----- compress-dir and the commands ----------------------------------------------------------
def test_compress_dir_codes_a_library_and_resumes(tmp_path, capsys):
    data = tmp_path / "lib"
    (data / "walks").mkdir(parents=True)
    for name in ("07_03.amc", "07.asf"):
        shutil.copy(DATA / name, data / "walks")
    shutil.copy(SMALL, data)
    out = tmp_path / "out"
    assert main(["compress-dir", str(data), str(out), "--codec", "kinwave", "--max-error-cm", "1", "--jobs", "2"]) == 0
    assert "2 clips written" in capsys.readouterr().out
    decoded = moc.decode(out / "walks" / "07_03.moc")
    assert decoded.num_frames == 415
    assert main(["compress-dir", str(data), str(out), "--codec", "kinwave", "--quiet"]) == 0
    assert "0 clips written" in capsys.readouterr().out


def test_compress_dir_refuses_two_clips_that_would_write_one_file(tmp_path):
    """07_03.bvh and 07_03.amc in one folder both make 07_03.moc: refused, naming both, with
    nothing written."""
    data = tmp_path / "lib"
    data.mkdir()
    for name in ("07_03.bvh", "07_03.amc", "07.asf"):
        shutil.copy(DATA / name, data)
    with pytest.raises(MocodecError, match=r"07_03\.(amc|bvh) and .*07_03\.(amc|bvh) would both be written to"):
        compressdir.plan(data, tmp_path / "out", "kinwave")
    assert not (tmp_path / "out").exists()


def test_compress_dir_reports_a_bad_clip_and_writes_the_others(tmp_path, capsys):
    data = tmp_path / "lib"
    data.mkdir()
    shutil.copy(SMALL, data)
    (data / "broken.bvh").write_text("not a bvh file\n")
    assert main(["compress-dir", str(data), str(tmp_path / "out"), "--codec", "dpcm", "--jobs", "1"]) == 1
    captured = capsys.readouterr()
    assert "1 clips written" in captured.out and "failed: " in captured.err and "broken.bvh" in captured.err
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == ["09_02.moc"]  # nothing half-written


def test_bench_command_writes_tables_and_refuses_unknown_codecs(tmp_path, capsys):
    assert (
        main(
            [
                "bench",
                str(SMALL),
                "--out",
                str(tmp_path),
                "--codecs",
                "zstd",
                "sz3",
                "--points",
                "knob",
                "--no-report",
                "--jobs",
                "1",
            ]
        )
        == 0
    )
    assert "6 rows from 1 clips" in capsys.readouterr().out
    assert (tmp_path / "results.csv").read_text().count("\n") == 7
    assert main(["bench", str(SMALL), "--out", str(tmp_path), "--codecs", "nope"]) == 2
    assert "unknown codec 'nope'" in capsys.readouterr().err


def test_codec_knobs_configure_the_codecs_that_have_them(tmp_path):
    run = suite.run(
        [SMALL], tmp_path, ["kinwave", "zstd"], ("error",), errors=(1.0,), report=False, jobs=1, knobs={"effort": "1"}
    )
    kin = next(r for r in run.rows if r["codec"] == "kinwave")
    assert run.meta["knobs"] == {"kinwave": {"effort": "1"}} and kin["max_joint_error_cm"] <= 1.0
    again = suite.run([SMALL], tmp_path, ["kinwave"], ("error",), errors=(1.0,), report=False, jobs=1)
    assert again.meta["tasks_run"] == 1  # other knobs: another task
    with pytest.raises(MocodecError, match="no codec of this run has the knob 'effort'"):
        suite.run([SMALL], tmp_path, ["zstd"], report=False, jobs=1, knobs={"effort": "1"})

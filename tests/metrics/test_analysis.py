"""Chapter-5 analysis: known answers on synthetic signals, and the CLI on real clips."""

from __future__ import annotations

import json

import numpy as np
import pytest

from conftest import DATA
from mocodec import save
from mocodec.analysis import analyze, density, spectrum, stats, temporal
from mocodec.cli import main
from mocodec.errors import MocodecError

FPS = 120.0


def test_usable_bits_follow_5_1_and_5_2():
    # noise one hardware step -> N_h = 0; range = full scale -> N_r = 0: all 16 bits
    assert stats.usable_bits(360.0, 360.0 / 2**16, 360.0) == 16
    # range R, noise sigma well above a step: log2(R / sigma)
    assert stats.usable_bits(131.2, 0.1, 360.0) == int(np.floor(np.log2(131.2 / 0.1)))
    assert stats.usable_bits(np.array([0.0, 70.0]), 70 / 256, 70.0, hardware_bits=8).tolist() == [0, 8]
    assert stats.raw_bit_rate(np.array([345, 168]), 30) == 15390  # the thesis's body + hands


def test_autocorrelation_of_a_sine_and_of_white_noise():
    n = 12000
    t = np.arange(n) / FPS
    acf = temporal.autocorrelation(np.sin(2 * np.pi * 1.0 * t), 120)[:, 0]
    assert acf[0] == 1 and acf[60] == pytest.approx(-1, abs=0.02) and acf[120] == pytest.approx(1, abs=0.02)
    white = temporal.autocorrelation(np.random.default_rng(0).normal(size=n), 20)[:, 0]
    assert np.abs(white[1:]).max() < 0.05


def test_markov_fit_recovers_a_gaussian_autocorrelation():
    lags = np.arange(40)
    fit = temporal.markov_fit(np.exp(-0.015 * lags**2), max_lag=10)
    assert fit.decay == pytest.approx(0.015) and fit.rms_error < 1e-12
    assert fit.decay_at(120.0, 30.0) == pytest.approx(0.015 * 16)


def test_stationarity_tells_a_steady_signal_from_a_drifting_one():
    t = np.arange(int(60 * FPS)) / FPS
    rng = np.random.default_rng(1)
    steady = np.sin(2 * np.pi * 0.5 * t) + 0.1 * rng.normal(size=t.size)
    drifting = steady + t / 10
    a = temporal.stationarity(np.column_stack([steady, drifting]), FPS)
    assert a.mean_drift[0] < 0.05 < 0.5 < a.mean_drift[1]
    assert a.acf_spread[0] < 0.1


def test_spectra_locate_a_band_limited_signal():
    t = np.arange(int(120 * FPS)) / FPS
    rng = np.random.default_rng(2)
    x = np.column_stack([np.sin(2 * np.pi * 2.0 * t + p) for p in rng.uniform(0, 6, 3)])
    x += 1e-4 * rng.normal(size=x.shape)  # -80 dB floor
    for s in (spectrum.welch(x, FPS), spectrum.blackman_tukey(x, FPS), spectrum.ar_spectrum(x, FPS)):
        assert s.freqs[np.argmax(s.power)] == pytest.approx(2.0, abs=0.3)
        assert spectrum.power_frequency(s, 0.99) < 3.0
    welch = spectrum.welch(x, FPS)
    assert 2.0 < spectrum.cutoff_frequency(welch, 40) < 10.0


def test_welch_power_integrates_to_the_variance():
    x = np.random.default_rng(3).normal(0, 2.0, (24000, 1))
    s = spectrum.welch(x, FPS)
    assert np.trapezoid(s.power, s.freqs) == pytest.approx(4.0, rel=0.05)
    bt = spectrum.blackman_tukey(x, FPS)
    assert np.trapezoid(bt.power, bt.freqs) == pytest.approx(4.0, rel=0.05)


def test_density_shapes():
    rng = np.random.default_rng(4)
    assert density.laplace_or_gauss(rng.laplace(size=20000)).best == "laplace"
    assert density.laplace_or_gauss(rng.normal(size=20000)).best == "gauss"
    d = density.pdf(rng.normal(size=5000), bins=40)
    assert np.sum(d.density * np.diff(d.edges)) == pytest.approx(1.0)
    joint, xe, ye = density.joint_pdf(rng.uniform(-90, 90, 1000), rng.uniform(-90, 90, 1000), bins=10)
    assert joint.shape == (10, 10) and np.sum(joint) * (xe[1] - xe[0]) * (ye[1] - ye[0]) == pytest.approx(1.0)


def test_analyze_a_walk(walk_amc):
    result = analyze(walk_amc)
    assert set(result["groups"]) >= {"torso", "left_arm", "left_leg"}
    leg = result["groups"]["left_leg"]
    assert 0 < leg["power_99_hz"] <= leg["cutoff_50db_hz"] <= 60
    assert result["usable_bitrate"] < result["raw_bitrate_32bit"]
    assert len(result["dofs"]) == walk_amc.num_channels
    json.dumps(result, allow_nan=False)


def test_cli_analyze_writes_json_and_plots(tmp_path, capsys):
    assert main(["analyze", str(DATA / "07_03.amc"), "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "99% power" in out and "left_leg" in out
    data = json.loads((tmp_path / "analysis.json").read_text())
    assert data["frames"] == 415
    for name in ("psd.png", "pdf.png", "stationarity.png", "joint_pdf.png"):
        assert (tmp_path / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert not list(tmp_path.glob("*.tmp"))


def test_cli_analyze_bad_file(tmp_path, capsys):
    bad = tmp_path / "bad.bvh"
    bad.write_text("HIERARCHY\nROOT x\n{\n")
    assert main(["analyze", str(bad)]) == 2
    assert "bad.bvh" in capsys.readouterr().err


@pytest.mark.parametrize("frames", [0, 2, 23])
def test_a_clip_too_short_to_analyse_gets_one_line(walk_bvh, tmp_path, capsys, frames):
    """Below twice the AR spectrum's order the spectra and fits have nothing to stand on (two
    frames crashed in a broadcast, none in a reduction): one line says how many it needs."""
    with pytest.raises(MocodecError, match=f"at least 24 frames .*the clip has {frames}$"):
        analyze(walk_bvh[:frames])
    save(walk_bvh[:frames], tmp_path / "short.bvh")
    assert main(["analyze", str(tmp_path / "short.bvh")]) == 2
    assert capsys.readouterr().err.count("\n") == 1
    analyze(walk_bvh[:24])

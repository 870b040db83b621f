import subprocess
import sys

import pytest

from mocodec import load
from mocodec.cli import main

from conftest import DATA


def test_info(capsys):
    assert main(["info", str(DATA / "07_03.amc"), "--joints"]) == 0
    out = capsys.readouterr().out
    assert "415 at 120 fps = 3.46 s" in out and "62 channels" in out and "238.1 kbit/s" in out
    assert "lfemur" in out and "left_leg" in out


def test_convert_both_ways(tmp_path, capsys):
    assert main(["convert", str(DATA / "07_03.amc"), str(tmp_path / "w.bvh")]) == 0
    assert main(["convert", str(tmp_path / "w.bvh"), str(tmp_path / "w.amc")]) == 0
    assert (tmp_path / "w.asf").exists()
    assert load(tmp_path / "w.amc").num_frames == 415


@pytest.mark.parametrize("argv, message", [
    (["info", "missing.bvh"], "missing.bvh: no such file"),
    (["convert", str(DATA / "09_02.bvh"), "out.xyz"], "expected .bvh or .amc"),
    (["info", str(DATA / "07.asf")], "skeleton only"),
])
def test_user_errors_print_one_line_and_exit_2(argv, message, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    proc = subprocess.run([sys.executable, "-m", "mocodec.cli", *argv], capture_output=True, text=True)
    assert proc.returncode == 2
    assert proc.stderr.count("\n") == 1 and message in proc.stderr and "Traceback" not in proc.stderr


def test_help_on_every_command():
    for cmd in ([], ["info"], ["convert"], ["demo"]):
        proc = subprocess.run([sys.executable, "-m", "mocodec.cli", *cmd, "--help"], capture_output=True, text=True)
        assert proc.returncode == 0 and "usage: mocodec" in proc.stdout


def test_demo_runs(capsys):
    assert main(["demo"]) == 0
    out = capsys.readouterr().out
    assert "round trip  BVH" in out and "round trip  AMC" in out


def test_compare_prints_every_measure(tmp_path, capsys):
    import json

    copy = tmp_path / "copy.bvh"
    assert main(["convert", str(DATA / "07_03.bvh"), str(copy)]) == 0
    capsys.readouterr()
    assert main(["compare", str(DATA / "07_03.bvh"), str(copy), "--per-joint"]) == 0
    out = capsys.readouterr().out
    for word in ("PSNR", "VPSNR", "joint error", "shell error", "foot sliding", "jerk", "(6-9)", "rShldr"):
        assert word in out
    assert main(["compare", str(DATA / "07_03.amc"), str(DATA / "07_03.amc"), "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["summary"]["max_joint_error_cm"] == 0 and data["summary"]["psnr_db"] is None   # lossless


def test_compare_rejects_mismatched_pairs(capsys):
    assert main(["compare", str(DATA / "07_03.bvh"), str(DATA / "07_03.amc")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "different skeletons" in err
    assert main(["compare", str(DATA / "07_03.bvh"), str(DATA / "09_02.bvh")]) == 2
    assert "frame counts" in capsys.readouterr().err

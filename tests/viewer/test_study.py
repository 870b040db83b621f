"""Perceptual studies: configurations, the DSCQS and 2AFC protocols, the report, and a whole
session clicked through in the browser."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from conftest import DATA, free_port
from mocodec.errors import FormatError, MocodecError
from mocodec.viewer import study


def write(tmp_path, doc: dict, name: str = "study.json"):
    (tmp_path / "walk.bvh").write_bytes((DATA / "07_03.bvh").read_bytes())
    path = tmp_path / name
    path.write_text(json.dumps({"clips": ["walk.bvh"], "max_frames": 240, **doc}))
    return path


def test_config_errors_name_the_file_and_the_problem(tmp_path):
    for doc, why in [
        ({"kind": "abx"}, "kind"),
        ({"kind": "dscqs"}, "cases"),
        ({"kind": "dscqs", "cases": [{"clip": 3, "codec": "dpcm"}]}, "case 0"),
        ({"kind": "dscqs", "cases": [{"clip": 0, "codec": "dpcm", "levels": 8}]}, "unknown key 'levels'"),
        ({"kind": "2afc", "step": 0}, "positive"),
        ({"kind": "2afc", "colour": 1}, "unknown setting"),
        ({"kind": "2afc", "rendering": "cartoon"}, "rendering"),
    ]:
        with pytest.raises(FormatError, match=why) as e:
            study.load_config(write(tmp_path, doc))
        assert "study.json" in str(e.value)


def test_staircase_two_up_one_down_and_threshold(tmp_path):
    cfg = study.load_config(
        write(
            tmp_path,
            {
                "kind": "2afc",
                "reversals": 4,
                "average_last": 3,
                "codec": "dpcm",
                "knob": "levels",
                "start": 40,
                "step": 4,
                "floor": 4,
            },
        )
    )
    s = study.start(cfg, "p1")
    answers = [True, True, True, True, False, True, True, False, False, True, True]
    values = []
    for correct in answers:
        if s.done:
            break
        s.trial()
        values.append(s.value)
        s.answer(
            {"choice": s.current["original"] if correct else ("left" if s.current["original"] == "right" else "right")}
        )
    # 40 -> two right: 36 -> two right: 32 -> wrong: 36 (reversal at 32) -> two right: 32 (reversal at 36)
    # -> wrong: 36 (reversal at 32) -> wrong: 40 -> two right: 36 (reversal at 40)
    assert values == [40, 40, 36, 36, 32, 36, 36, 32, 36, 40, 40]
    assert s.reversals == [32, 36, 32, 40] and s.done
    assert s.threshold == pytest.approx((36 + 32 + 40) / 3)
    with pytest.raises(MocodecError):
        s.answer({"choice": "up"})


def test_dscqs_maps_a_and_b_back_to_reference_and_coded(tmp_path):
    cfg = study.load_config(
        write(
            tmp_path,
            {
                "kind": "dscqs",
                "seed": 3,
                "cases": [{"clip": 0, "codec": "spiht", "ratio": 20}, {"clip": 0, "codec": "spiht", "ratio": 40}],
            },
        )
    )
    s = study.start(cfg, "p1")
    refs = []
    while not s.done:
        t = s.trial()
        ref = s.current["reference"]
        refs.append(ref)
        assert t["A"] != t["B"] and t["sequence"] == ["A", "B", "A", "B"]
        s.answer({"scores": {ref: 5, ("B" if ref == "A" else "A"): 3}})
    assert [t["difference"] for t in s.trials] == [2, 2]
    assert all(abs(t["ratio"] - r) < 0.02 * r for t, r in zip(s.trials, (20, 40)))
    path = s.save(tmp_path / "out")
    again = study.start(cfg, "p2")
    assert [bool(x) for x in again.reference_first] == [r == "A" for r in refs]  # seeded order
    with pytest.raises(MocodecError):
        s.answer({"scores": {"A": 9, "B": 1}})
    assert json.loads(path.read_text())["trials"][0]["score_reference"] == 5


def test_report_dmos_and_thresholds_with_confidence_intervals(tmp_path):
    files = []
    for k, (d, t) in enumerate([(1, 0.010), (2, 0.014), (0, 0.012)]):
        f = tmp_path / f"d{k}.json"
        f.write_text(
            json.dumps(
                {
                    "kind": "dscqs",
                    "trials": [{"clip": "walk.bvh", "codec": {"codec": "spiht"}, "ratio": 60.0, "difference": d}],
                }
            )
        )
        g = tmp_path / f"t{k}.json"
        g.write_text(json.dumps({"kind": "2afc", "threshold": t, "trials": []}))
        files += [f, g]
    r = study.report(files)
    dmos = r["dmos"]["walk.bvh spiht 60.0:1"]
    assert dmos["n"] == 3 and dmos["mean"] == pytest.approx(1.0)
    half = 4.302652729911275 * 1.0 / np.sqrt(3)  # t(0.975, 2) * sd / sqrt(n)
    assert dmos["ci95"] == pytest.approx([1 - half, 1 + half])
    assert r["threshold_t_lower"]["mean"] == pytest.approx(0.012)
    bad = tmp_path / "bad.json"
    bad.write_text("{}")
    with pytest.raises(FormatError, match="bad.json"):
        study.report([bad])


def run_session(config, out, browser, clicks):
    port = free_port()
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "mocodec",
            "study",
            "run",
            str(config),
            "--out",
            str(out),
            "--participant",
            "p7",
            "--port",
            str(port),
            "--no-browser",
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        assert "viewer on" in proc.stdout.readline(), proc.stderr.read()
        page = browser.new_page(viewport={"width": 1100, "height": 800})
        errors = []
        page.on("pageerror", lambda e: errors.append(str(e)))
        page.goto(f"http://127.0.0.1:{port}/")
        clicks(page)
        page.wait_for_function("window.studyState.phase === 'done'", timeout=60_000)
        saved = page.evaluate("window.studyState.saved")
        assert not errors, errors
        page.close()
        return json.loads(open(saved).read())
    finally:
        proc.terminate()
        proc.wait(10)


def _answered(page, button: str) -> None:
    """Click ``button`` and wait until the page has moved past the trial: its index changed, or
    the session is done. (Not "the phase left 'choosing'": the answer and the next trial can
    both arrive between two polls, and the next trial is 'choosing' again.)"""
    before = page.evaluate("window.studyState.index")
    page.click(button)
    page.wait_for_function(
        f"window.studyState.index !== {before} || window.studyState.phase === 'done'", timeout=60_000
    )


def test_a_dscqs_session_is_completed_by_clicks_and_saved(tmp_path, browser):
    config = write(
        tmp_path,
        {
            "kind": "dscqs",
            "speed": 4,
            "cases": [
                {"clip": 0, "codec": "spiht", "ratio": 40},
                {"clip": 0, "codec": "dpcm", "knobs": {"levels": 16}},
            ],
        },
    )

    def clicks(page):
        page.wait_for_function("window.studyState.phase === 'playing'", timeout=60_000)
        assert page.evaluate("window.studyState.rendering") == "body"  # the mannequin, by default
        for _ in range(2):
            page.wait_for_function("window.studyState.phase === 'scoring'", timeout=60_000)
            page.click(".score-row[data-clip=A] button[data-score='4']")
            page.click(".score-row[data-clip=B] button[data-score='2']")
            _answered(page, "#next")

    result = run_session(config, tmp_path / "out", browser, clicks)
    assert result["kind"] == "dscqs" and result["participant"] == "p7" and len(result["trials"]) == 2
    assert result["config"]["rendering"] == "body"
    for t in result["trials"]:
        assert t["difference"] == (2 if t["reference"] == "A" else -2) and t["rendering"] == "body"


def test_a_2afc_staircase_is_completed_by_clicks_and_saved(tmp_path, browser):
    config = write(
        tmp_path,
        {"kind": "2afc", "speed": 4, "max_trials": 4, "reversals": 3, "average_last": 3, "rendering": "sticks"},
    )

    def clicks(page):
        for _ in range(4):
            page.wait_for_function("window.studyState.phase === 'choosing'", timeout=60_000)
            assert page.evaluate("window.studyState.rendering") == "sticks"
            _answered(page, "#pick-left")

    result = run_session(config, tmp_path / "out", browser, clicks)
    assert result["kind"] == "2afc" and len(result["trials"]) == 4
    assert result["trials"][0]["value"] == pytest.approx(0.024)
    assert all(t["choice"] == "left" and t["correct"] == (t["original"] == "left") for t in result["trials"])
    assert all(t["rendering"] == "sticks" for t in result["trials"])

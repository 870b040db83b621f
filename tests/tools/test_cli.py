import json
import subprocess
import sys

import numpy as np
import pytest

from conftest import DATA
from mocodec import load, save
from mocodec.cli import main


def test_info(capsys):
    assert main(["info", str(DATA / "07_03.amc"), "--joints"]) == 0
    out = capsys.readouterr().out
    assert "415 at 120 fps, spanning 3.450 s" in out and "62 channels" in out and "238.1 kbit/s" in out
    assert "lfemur" in out and "left_leg" in out


def test_info_reads_a_bvh_in_the_unit_given(capsys):
    assert main(["info", str(DATA / "07_03.bvh"), "--units", "in"]) == 0
    assert "39.3701 per metre" in capsys.readouterr().out
    with pytest.raises(SystemExit) as exit_:
        main(["info", str(DATA / "07_03.bvh"), "--units", "furlongs"])
    assert exit_.value.code == 2
    assert "'furlongs' is not a unit (m, cm, mm, in)" in capsys.readouterr().err


def test_convert_refuses_to_leave_a_file_whose_motion_differs_from_what_it_read(tmp_path, capsys, monkeypatch):
    from mocodec.formats import bvh

    format_rows = bvh.format_rows
    monkeypatch.setattr(bvh, "format_rows", lambda values, decimals: format_rows(values[:, ::-1], decimals))
    out = tmp_path / "walk.bvh"
    assert main(["convert", str(DATA / "07_03.amc"), str(out)]) == 2
    err = capsys.readouterr().err
    assert "reads back" in err and "not written" in err and err.count("\n") == 1
    assert not out.exists()
    monkeypatch.undo()
    assert main(["convert", str(DATA / "07_03.amc"), str(out)]) == 0
    assert "joints within" in capsys.readouterr().out and out.exists()


def test_info_on_a_moc_file_reads_its_header_only(tmp_path, capsys):
    path = tmp_path / "w.moc"
    assert main(["encode", str(DATA / "07_03.amc"), "-o", str(path), "--codec", "raw"]) == 0
    capsys.readouterr()
    assert main(["info", str(path)]) == 0
    out = capsys.readouterr().out
    size = path.stat().st_size
    assert "codec       raw" in out and "415 at 120 fps" in out and "62 channels" in out
    assert f"ratio {415 * 62 * 4 / size:.2f} vs 32-bit floats" in out
    ref = tmp_path / "ref.moc"
    assert main(["encode", str(DATA / "07_03.amc"), "-o", str(ref), "--codec", "raw", "--skeleton-ref"]) == 0
    assert main(["info", str(ref)]) == 2  # the skeleton is not in the file
    assert main(["info", str(ref), "--skeleton", str(DATA / "07.asf")]) == 0
    assert "62 channels" in capsys.readouterr().out
    path.write_bytes(path.read_bytes()[:40])
    assert main(["info", str(path)]) == 2  # a damaged file: one line, no traceback
    assert "w.moc" in capsys.readouterr().err


def test_convert_both_ways(tmp_path, capsys):
    assert main(["convert", str(DATA / "07_03.amc"), str(tmp_path / "w.bvh")]) == 0
    assert main(["convert", str(tmp_path / "w.bvh"), str(tmp_path / "w.amc")]) == 0
    assert (tmp_path / "w.asf").exists()
    assert load(tmp_path / "w.amc").num_frames == 415


@pytest.mark.parametrize(
    "argv, message",
    [
        (["info", "missing.bvh"], "missing.bvh: no such file"),
        (["decode", "missing.moc", "-o", "x.bvh"], "error: missing.moc: No such file or directory"),  # not "[Errno 2]"
        (["convert", str(DATA / "09_02.bvh"), "out.xyz"], "expected .bvh, .amc, .gltf, .glb"),
        (["info", str(DATA / "07.asf")], "skeleton only"),
        # checked before a recording, not after it; a NaN camera never reaches the relay
        (["subscribe", "--url", "ws://127.0.0.1:1", "--room", "r", "--token", "t", "-o", "x.xyz"], "cannot write .xyz"),
        (
            [
                "subscribe",
                "--url",
                "ws://127.0.0.1:1",
                "--room",
                "r",
                "--token",
                "t",
                "-o",
                "x.bvh",
                "--camera",
                "nan,0,0",
            ],
            "--camera must be finite",
        ),
    ],
)
def test_user_errors_print_one_line_and_exit_2(argv, message, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    proc = subprocess.run([sys.executable, "-m", "mocodec", *argv], capture_output=True, text=True)
    assert proc.returncode == 2
    assert proc.stderr.count("\n") == 1 and message in proc.stderr and "Traceback" not in proc.stderr


@pytest.mark.parametrize(
    "argv, message",
    [
        (["serve", "--port", "99999"], "argument --port: 99999 is out of range: at least 0, at most 65535"),
        (["serve", "--tick-hz", "0"], "argument --tick-hz: 0 is out of range: above 0, at most 1000"),
        (["serve", "--workers", "0"], "argument --workers: 0 is out of range: at least 1, at most 256"),
        (["serve", "--max-bytes-per-s", "nan"], "argument --max-bytes-per-s: nan is out of range: above 0"),
        (["token", "--room", "r", "--ttl", "-5"], "argument --ttl: -5 is out of range: above 0"),
        (["view", "--port", "x"], "argument --port: 'x' is not an integer"),
        (["subscribe", "--url", "u", "--room", "r", "--token", "t", "-o", "o.bvh", "--stream", "-1"], "--stream: -1"),
    ],
)
def test_numbers_out_of_range_are_usage_errors(argv, message, capsys):
    """A port of 99999 or a tick rate of 0 reached the server as a traceback (OverflowError,
    ZeroDivisionError); they are usage errors that say the range."""
    with pytest.raises(SystemExit) as exited:
        main(argv)
    assert exited.value.code == 2 and message in capsys.readouterr().err


def test_help_on_every_command():
    from mocodec.cli import COMMANDS

    proc = subprocess.run([sys.executable, "-m", "mocodec", "--help"], capture_output=True, text=True)
    assert proc.returncode == 0 and all(name in proc.stdout for name in COMMANDS)
    for name in COMMANDS:
        with pytest.raises(SystemExit) as done:
            main([name, "--help"])
        assert done.value.code == 0


def test_the_full_parser_has_every_command_with_its_help_line():
    from mocodec.cli import COMMANDS, build_parser

    text = build_parser("all").format_help()
    assert all(name in text and help_line.split()[0] in text for name, (_, help_line) in COMMANDS.items())


def test_help_imports_no_command_module():
    code = "import sys; from mocodec.cli import build_parser; build_parser(); print(sorted(sys.modules))"
    modules = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert "numpy" not in modules and "mocodec.codecs.base" not in modules and "mocodec.cli.files" not in modules


def test_model_training_defaults_are_the_training_modules_own():
    from mocodec.cli import build_parser
    from mocodec.codecs.model import motiontables, segmentation
    from mocodec.codecs.motionprimitives import primdb, rhythmdb

    def parsed(kind):
        return build_parser("model").parse_args(["model", "train", kind, "clip.bvh", "-o", "model.bin"])

    tables, gesture = parsed("tables"), segmentation.GestureParams()
    assert (tables.spacing, tables.discard, tables.norm, tables.interior) == (
        motiontables.SPACING_CM,
        motiontables.DISCARD_DEG,
        motiontables.NORM,
        motiontables.INTERIOR_WEIGHT,
    )
    assert (tables.beta, tables.window, tables.min_length, tables.max_length) == (
        gesture.beta,
        gesture.window,
        gesture.min_length,
        gesture.max_length,
    )
    prims = parsed("primitives")
    assert (prims.threshold, prims.max_clusters) == (primdb.ERROR_THRESHOLD, primdb.MAX_CLUSTERS)
    assert parsed("rhythm").count == rhythmdb.COUNT


def test_demo_runs(capsys):
    assert main(["demo"]) == 0
    out = capsys.readouterr().out
    for word in ("ratio", "bit rate", "PSNR", "joint error", "us per frame", "kinwave"):
        assert word in out


def test_warmup_compiles_a_codecs_shared_parts_in_a_second_process(capsys):
    """`mocodec warmup kinwave` codes a second of the bundled clip while a second process
    compiles kinwave's warm parts (the coefficient coder); every codec's parts are module-level
    functions, which a spawned process can be handed."""
    import pickle

    from mocodec.codecs import codec_class, codec_ids
    from mocodec.coding.entropy import coefcoder

    assert coefcoder.warm in codec_class("kinwave").warm_parts
    for cid in codec_ids():
        for part in codec_class(cid).warm_parts:
            assert pickle.loads(pickle.dumps(part)) is part
    assert main(["warmup", "kinwave"]) == 0
    assert "compiled or loaded the kernels of 1 codecs" in capsys.readouterr().out


def test_a_rig_without_channels_encodes_decodes_and_is_not_evaluated(tmp_path, capsys):
    """A rig whose joints never move (no channels) codes to a file and back; ``eval`` says there
    is nothing to measure, in one line, with a non-zero exit."""
    still = tmp_path / "still.bvh"
    still.write_text("HIERARCHY\nROOT hip\n{\n OFFSET 0 0 0\n CHANNELS 0\n}\nMOTION\nFrames: 2\nFrame Time: 0.04\n\n\n")
    assert main(["encode", str(still), "-o", str(tmp_path / "still.moc")]) == 0
    assert main(["decode", str(tmp_path / "still.moc"), "-o", str(tmp_path / "back.bvh")]) == 0
    assert load(tmp_path / "back.bvh").num_frames == 2
    capsys.readouterr()
    assert main(["eval", str(still)]) == 2
    assert "no channels" in capsys.readouterr().err


def test_a_clip_of_no_frames_codes_decodes_and_converts(tmp_path, capsys):
    """A BVH of "Frames: 0" (a rig and no take) codes to a file and back and converts to AMC and
    back; the encode line says it has no frames instead of dividing by its duration, and
    ``eval`` says there is nothing to compare, in one line."""
    empty = tmp_path / "empty.bvh"
    text = (DATA / "07_03.bvh").read_text()
    empty.write_text(text[: text.index("Frames:")] + "Frames: 0\nFrame Time: 0.0083333\n")
    for codec in ("kinwave", "raw"):
        assert main(["encode", str(empty), "-o", str(tmp_path / f"{codec}.moc"), "--codec", codec]) == 0
        assert "0 frames" in capsys.readouterr().out
        assert main(["decode", str(tmp_path / f"{codec}.moc"), "-o", str(tmp_path / f"{codec}.bvh")]) == 0
        back = load(tmp_path / f"{codec}.bvh")
        assert back.num_frames == 0 and back.skeleton.names == load(empty).skeleton.names
        assert main(["info", str(tmp_path / f"{codec}.moc")]) == 0
        assert "vs 32-bit floats, no frames" in capsys.readouterr().out
    assert main(["convert", str(empty), str(tmp_path / "empty.amc")]) == 0
    assert main(["convert", str(tmp_path / "empty.amc"), str(tmp_path / "again.bvh")]) == 0
    assert load(tmp_path / "again.bvh").num_frames == 0
    capsys.readouterr()
    assert main(["eval", str(empty)]) == 2
    assert capsys.readouterr().err.count("\n") == 1


def test_encode_decode_eval_codecs(tmp_path, capsys):
    out = tmp_path / "walk.moc"
    assert main(["encode", str(DATA / "07_03.amc"), "-o", str(out)]) == 0
    assert "ratio" in capsys.readouterr().out and out.exists()
    back = tmp_path / "back.bvh"
    assert main(["decode", str(out), "-o", str(back), "--frames", "100:200"]) == 0
    assert load(back).num_frames == 100
    assert main(["decode", str(out), "-o", str(tmp_path / "tail.amc"), "--frames", "400:"]) == 0
    assert load(tmp_path / "tail.amc").num_frames == 15
    capsys.readouterr()
    assert (
        main(["encode", str(DATA / "07_03.amc"), str(DATA / "135_08.amc"), "-o", str(tmp_path), "--codec", "raw"]) == 0
    )
    assert (tmp_path / "135_08.moc").exists()
    assert main(["eval", str(DATA / "07_03.bvh"), "--codec", "raw"]) == 0
    text = capsys.readouterr().out
    assert "ratio" in text and "VPSNR" in text and "us per frame" in text
    assert main(["codecs"]) == 0
    assert "lossless" in capsys.readouterr().out


def test_encode_refuses_two_inputs_that_would_write_one_file(tmp_path, capsys):
    """``07_03.bvh`` and ``07_03.amc`` (or two folders' ``walk.bvh``) both make ``07_03.moc``:
    the second replaced the first with exit 0; now nothing is written and the pair is named."""
    out = tmp_path / "out"
    out.mkdir()
    assert main(["encode", str(DATA / "07_03.bvh"), str(DATA / "07_03.amc"), "-o", str(out)]) == 2
    assert "would both be written to" in capsys.readouterr().err and not list(out.iterdir())


def test_a_coded_file_is_never_written_under_a_motion_files_name(tmp_path, capsys):
    """``encode clip.bvh -o clip.bvh`` replaced the clip with its lossy .moc, exit 0; encode and
    truncate refuse a motion file's name (any other name is the user's choice), and the clip
    stays as it was."""
    clip = tmp_path / "clip.bvh"
    clip.write_bytes((DATA / "07_03.bvh").read_bytes())
    assert main(["encode", str(clip), "-o", str(clip)]) == 2
    assert "a coded file would replace a motion file there; name it .moc" in capsys.readouterr().err
    assert clip.read_bytes() == (DATA / "07_03.bvh").read_bytes()
    assert main(["encode", str(clip), "-o", str(tmp_path / "coded.moc"), "--codec", "spiht"]) == 0
    assert main(["truncate", str(tmp_path / "coded.moc"), "-o", str(tmp_path / "small.amc"), "--ratio", "40"]) == 2
    assert not (tmp_path / "small.amc").exists()
    assert main(["truncate", str(tmp_path / "coded.moc"), "-o", str(tmp_path / "small"), "--ratio", "40"]) == 0


def test_coding_errors_are_one_line(tmp_path, capsys):
    cases = [
        (["encode", str(DATA / "07_03.amc"), "-o", str(tmp_path / "x.moc"), "--codec", "nope"], "unknown codec"),
        (["encode", str(DATA / "07_03.amc"), "-o", str(tmp_path / "x.moc"), "--colour", "3"], "unknown knob"),
        (
            ["encode", str(DATA / "07_03.amc"), "-o", str(tmp_path / "x.moc"), "--codec", "lossless", "--ratio", "50"],
            "no quality knob",
        ),
        (["encode", str(DATA / "07_03.amc"), str(DATA / "135_08.amc"), "-o", str(tmp_path / "x.moc")], "directory"),
        (["decode", str(DATA / "07_03.amc"), "-o", str(tmp_path / "x.bvh")], "not a .moc file"),
        (["decode", str(tmp_path / "missing.moc"), "-o", str(tmp_path / "x.bvh")], "missing.moc"),
    ]
    for argv, message in cases:
        assert main(argv) == 2, argv
        err = capsys.readouterr().err
        assert message in err and err.count("\n") == 1, err
    assert not list(tmp_path.glob("*.moc")) and not list(tmp_path.glob(".*tmp"))


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
    assert data["summary"]["max_joint_error_cm"] == 0 and data["summary"]["psnr_db"] is None  # lossless


def test_compare_takes_a_bvh_whose_end_sites_lost_their_fbx_names(tmp_path, capsys):
    """An FBX names its leaf bone ("Head"); BVH end sites have no name, and its reader calls
    them after their parent: the converted file compares with its original (it was refused
    as a different skeleton), and the skeletons still differ where names count."""
    fbx = DATA.parent / "formats" / "fbx" / "nod.fbx"
    assert main(["convert", str(fbx), str(tmp_path / "nod.bvh")]) == 0
    original, converted = load(fbx).skeleton, load(tmp_path / "nod.bvh").skeleton
    assert "name 'Head'" in original.difference(converted, atol=1e-4)
    assert original.difference(converted, atol=1e-4, end_site_names=False) is None
    capsys.readouterr()
    assert main(["compare", str(fbx), str(tmp_path / "nod.bvh")]) == 0
    assert "joint error" in capsys.readouterr().out


def test_compare_decodes_a_moc_file_itself(tmp_path, capsys):
    """``compare clip.bvh clip.moc`` decodes the coded file (it was refused as an unknown file
    type); one coded with --skeleton-ref takes the original's skeleton, and the bound holds."""
    for extra in ([], ["--skeleton-ref"]):
        coded = tmp_path / f"walk{len(extra)}.moc"
        assert main(["encode", str(DATA / "07_03.bvh"), "-o", str(coded), "--max-error-cm", "1", *extra]) == 0
        capsys.readouterr()
        assert main(["compare", str(DATA / "07_03.bvh"), str(coded), "--json"]) == 0
        summary = json.loads(capsys.readouterr().out)["summary"]
        assert 0 < summary["max_joint_error_cm"] <= 1.0


def test_compare_rejects_mismatched_pairs(capsys):
    assert main(["compare", str(DATA / "07_03.bvh"), str(DATA / "07_03.amc")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "different skeletons" in err
    assert main(["compare", str(DATA / "07_03.bvh"), str(DATA / "09_02.bvh")]) == 2
    assert "frame counts" in capsys.readouterr().err


def test_truncate_command(tmp_path, capsys):
    full = tmp_path / "full.moc"
    assert (
        main(["encode", str(DATA / "07_03.amc"), "-o", str(full), "--codec", "spiht", "--bits-per-second", "30000"])
        == 0
    )
    assert main(["truncate", str(full), "--ratio", "25", "-o", str(tmp_path / "small.moc")]) == 0
    assert "ratio 2" in capsys.readouterr().out
    assert main(["decode", str(tmp_path / "small.moc"), "-o", str(tmp_path / "small.bvh")]) == 0


def test_truncate_below_what_the_side_data_take_says_so(tmp_path, capsys):
    """A short file cut to a size its skeleton and side data already pass: the search kept to
    the rate knob's floor and says what it could not reach (it went under the floor and named
    the knob, which the user never set)."""
    save(load(DATA / "07_03.bvh")[:4], tmp_path / "short.bvh")
    assert main(["encode", str(tmp_path / "short.bvh"), "-o", str(tmp_path / "s.moc"), "--codec", "spiht"]) == 0
    capsys.readouterr()
    assert main(["truncate", str(tmp_path / "s.moc"), "--ratio", "20", "-o", str(tmp_path / "t.moc")]) == 2
    err = capsys.readouterr().err
    assert "cannot cut to" in err and "bits_per_second" not in err and err.count("\n") == 1
    assert not (tmp_path / "t.moc").exists()


def test_skeleton_reference_on_the_command_line(tmp_path, capsys):
    out = tmp_path / "ref.moc"
    assert main(["encode", str(DATA / "07_03.amc"), "-o", str(out), "--skeleton-ref"]) == 0
    assert main(["decode", str(out), "-o", str(tmp_path / "x.bvh")]) == 2
    assert "--skeleton" in capsys.readouterr().err
    assert main(["decode", str(out), "-o", str(tmp_path / "x.bvh"), "--skeleton", str(DATA / "07.asf")]) == 0
    assert load(tmp_path / "x.bvh").num_frames == 415


@pytest.mark.parametrize("codec", ["kinwave", "kinwave-live"])
def test_a_bound_the_codec_guarantees_sets_its_knob_with_no_search(codec, tmp_path, monkeypatch, capsys):
    from mocodec import moc, ratecontrol

    def no_search(*args, **kwargs):
        raise AssertionError("rate control searched a codec that guarantees the bound itself")

    monkeypatch.setattr(ratecontrol, "tune", no_search)
    out = tmp_path / "w.moc"
    assert main(["encode", str(DATA / "07_03.amc"), "-o", str(out), "--codec", codec, "--max-error-cm", "2"]) == 0
    assert moc.info(out).header["codec"]["knobs"]["max_error_cm"] == 2.0
    decoded = moc.decode(out)
    motion = load(DATA / "07_03.amc")
    error_cm = np.linalg.norm(decoded.positions_m() - motion.positions_m(), axis=2).max() * 100
    assert error_cm <= 2.0 + 1e-6


def test_encode_codes_a_files_chunks_in_several_processes_to_the_same_bytes(tmp_path, capsys):
    one, two = tmp_path / "one.moc", tmp_path / "two.moc"
    common = ["--chunk-frames", "100", "--max-error-cm", "1"]
    assert main(["encode", str(DATA / "07_03.amc"), "-o", str(one), *common]) == 0
    assert main(["encode", str(DATA / "07_03.amc"), "-o", str(two), *common, "--jobs", "2"]) == 0
    assert one.read_bytes() == two.read_bytes()
    assert main(["encode", str(DATA / "07_03.amc"), "-o", str(two), "--jobs", "0"]) == 2
    assert "jobs must be at least 1" in capsys.readouterr().err


def test_compare_reads_a_converted_file_in_its_own_unit(tmp_path, capsys):
    """A BVH written in centimetres of a motion in another unit compares with it as it is."""
    from mocodec import save
    from mocodec.formats import with_units

    out = tmp_path / "m.bvh"
    save(with_units(load(DATA / "07_03.bvh")[:60], 0.4), tmp_path / "metres.glb")  # a unit no guess finds
    assert main(["convert", str(tmp_path / "metres.glb"), str(out)]) == 0
    capsys.readouterr()
    assert main(["compare", str(tmp_path / "metres.glb"), str(out), "--json"]) == 0
    assert '"max_joint_error_cm"' in capsys.readouterr().out


def test_codecs_lists_each_id_in_a_column_of_its_own(capsys):
    """The first column of ``mocodec codecs`` is the ids, whatever their length (a script reads
    it); the knob lines start with spaces."""
    from mocodec.codecs import codec_ids

    assert main(["codecs"]) == 0
    lines = capsys.readouterr().out.splitlines()
    heads = [line for line in lines if not line.startswith(" ")]
    width = max(map(len, codec_ids())) + 2
    assert [line[:width].rstrip() for line in heads] == codec_ids()
    assert all(line[width] != " " for line in heads)  # the description starts in one column
    assert len(lines) == 2 * len(heads)


def test_publishing_with_a_codec_that_holds_frames_back_says_how_late():
    """kinwave sends a packet per segment (1024 frames by default): publishing with it names
    the delay viewers will see; a short window or kinwave-live says nothing."""
    pytest.importorskip("aiohttp")
    from mocodec.cli.stream import late_notice
    from mocodec.codecs import get_codec

    assert "1024 frames" in late_notice(get_codec("kinwave"), 120.0)
    assert "8.5 s late" in late_notice(get_codec("kinwave"), 120.0)
    assert late_notice(get_codec("kinwave", window=64), 120.0) is None
    assert late_notice(get_codec("kinwave-live"), 120.0) is None

import numpy as np
import pytest

from conftest import DATA
from mocodec import ConversionError, FormatError, load, moc, save
from mocodec.codecs import get_codec
from mocodec.formats import read_asf, to_asf_form, to_bvh_form, write_bvh
from mocodec.formats.bvh import guess_units_per_metre

SMALL_BVH = """HIERARCHY
ROOT Hips
{
\tOFFSET 0 0 0
\tCHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
\tJOINT Chest
\t{
\t\tOFFSET 0 10 0
\t\tCHANNELS 3 Xrotation Zrotation Yrotation
\t\tJOINT Arm
\t\t{
\t\t\tOFFSET 5 0 0
\t\t\tCHANNELS 4 Xposition Yrotation Xrotation Zrotation
\t\t\tEnd Site
\t\t\t{
\t\t\t\tOFFSET 0 -5 0
\t\t\t}
\t\t}
\t}
}
MOTION
Frames: 2
Frame Time: 0.0333333
0 90 0 10 20 30 1 2 3 0.5 4 5 6
1 91 1 11 21 31 2 3 4 0.5 5 6 7
"""


def write(tmp_path, name, text):
    p = tmp_path / name
    p.write_text(text)
    return p


def test_bvh_any_order_position_channels_end_sites_tabs(tmp_path):
    m = load(write(tmp_path, "a.bvh", SMALL_BVH))
    sk = m.skeleton
    assert sk.names == ("Hips", "Chest", "Arm", "Arm_end")
    assert sk.joints[2].channels == ("Xposition", "Yrotation", "Xrotation", "Zrotation")
    assert sk.joints[2].rotation_order == "YXZ"
    assert m.fps == 30.0 and m.num_frames == 2
    np.testing.assert_array_equal(m.channels[1, :3], [1, 91, 1])
    out = tmp_path / "b.bvh"
    write_bvh(m, out)
    assert load(out).isclose(m)


def test_bvh_written_back_keeps_each_joints_channel_order(tmp_path):
    """A root whose rotations come before its positions (as some exporters write it) is BVH
    already: saved again, and through a .moc file, its channels keep their order, so the file
    has the layout its pipeline wrote and compares with the original joint for joint."""
    text = SMALL_BVH.replace(
        "CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation",
        "CHANNELS 6 Zrotation Xrotation Yrotation Xposition Yposition Zposition",
    )
    m = load(write(tmp_path, "rotations_first.bvh", text))
    assert m.skeleton.joints[0].channels[:3] == ("Zrotation", "Xrotation", "Yrotation")
    save(m, tmp_path / "again.bvh")
    assert (tmp_path / "again.bvh").read_text().splitlines()[4].split() == text.splitlines()[4].split()
    again = load(tmp_path / "again.bvh")
    assert again.skeleton == m.skeleton
    np.testing.assert_allclose(again.channels, m.channels, atol=1e-6)
    coded = moc.unpack(moc.pack(m, get_codec("raw")))
    save(coded, tmp_path / "decoded.bvh")
    assert load(tmp_path / "decoded.bvh").skeleton == m.skeleton


@pytest.mark.parametrize(
    "encode",
    [
        lambda t: b"\xef\xbb\xbf" + t.encode(),  # a UTF-8 byte-order mark
        lambda t: t.encode("utf-16"),  # a Windows editor's "Unicode"
        lambda t: b"\xfe\xff" + t.encode("utf-16-be"),
    ],
    ids=["utf-8 bom", "utf-16", "utf-16 big-endian"],
)
def test_text_with_a_byte_order_mark_reads_as_without(tmp_path, encode, walk_amc):
    plain = load(write(tmp_path, "plain.bvh", SMALL_BVH))
    (tmp_path / "marked.bvh").write_bytes(encode(SMALL_BVH))
    assert load(tmp_path / "marked.bvh").isclose(plain)
    (tmp_path / "marked.asf").write_bytes(encode((DATA / "07.asf").read_text()))
    (tmp_path / "marked.amc").write_bytes(encode((DATA / "07_03.amc").read_text()))
    assert load(tmp_path / "marked.amc", asf=tmp_path / "marked.asf").isclose(walk_amc)


def test_utf16_that_does_not_decode_names_its_byte(tmp_path):
    (tmp_path / "bad.bvh").write_bytes(b"\xff\xfe" + SMALL_BVH.encode("utf-16-le") + b"\x00\xd8")
    with pytest.raises(FormatError, match=r"bad.bvh: not UTF-16 text after its byte-order mark \(at byte \d+\)"):
        load(tmp_path / "bad.bvh")


def test_bvh_crlf_and_spaces(tmp_path):
    text = SMALL_BVH.replace("\t", "    ").replace("\n", "\r\n")
    assert load(write(tmp_path, "crlf.bvh", text)).isclose(load(write(tmp_path, "lf.bvh", SMALL_BVH)))


@pytest.mark.parametrize(
    "edit, line, message",
    [
        (lambda t: t.replace("OFFSET 0 10 0", "OFSET 0 10 0"), 8, "unknown keyword 'OFSET'"),
        (lambda t: t.replace("0 90 0 10 20 30 1 2 3 0.5 4 5 6", "0 90 0 10 20 30 1 2 3 0.5 4 5"), 24, "12 values"),
        (lambda t: t.replace("Frames: 2", "Frames: 3"), 22, "'Frames: 3' but 2 frame lines"),
        (lambda t: t.replace("1 91 1 11", "1 91 x 11"), 25, "'x' is not a number"),
        (lambda t: t.replace("1 91 1 11", "1 91 nan 11"), 25, "non-finite"),
        (lambda t: t.replace("HIERARCHY", "HIERARCH"), 1, "expected 'HIERARCHY'"),
        (lambda t: t.replace("Zrotation Xrotation Yrotation", "Zrotation Xrotation Wrotation"), 5, "unknown channel"),
        (lambda t: t.replace("CHANNELS 3 Xrotation", "CHANNELS 4 Xrotation"), 9, "lists 3 channel names"),
        (lambda t: t.replace("Frame Time: 0.0333333", "Frame Time: 0"), 23, "must be positive"),
        (lambda t: t.replace("\t\t}\n\t}\n}", "\t\t}\n\t}\n"), 21, "missing '}'"),
        (lambda t: t.replace("OFFSET 5 0 0", "OFFSET 5 0"), 12, "OFFSET needs 3 numbers"),
    ],
)
def test_bvh_errors_name_file_line_and_expectation(tmp_path, edit, line, message):
    path = write(tmp_path, "bad.bvh", edit(SMALL_BVH))
    with pytest.raises(FormatError) as exc:
        load(path)
    assert exc.value.line == line, str(exc.value)
    assert message in str(exc.value)
    assert str(path) in str(exc.value)


@pytest.mark.parametrize(
    "content, message",
    [
        (b"", "empty file"),
        (b"   \n\n", "empty file"),
        (b"\x00\x01\x02binary\xff", "binary data"),
    ],
)
def test_empty_and_binary_files(tmp_path, content, message):
    for ext in (".bvh", ".amc", ".asf"):
        p = tmp_path / f"x{ext}"
        p.write_bytes(content)
        if ext == ".amc":
            (tmp_path / "x.asf").write_bytes(content)
        with pytest.raises(FormatError, match=message):
            read_asf(p) if ext == ".asf" else load(p)


def test_unknown_extension_and_asf_as_motion(tmp_path):
    with pytest.raises(FormatError, match="unknown file type"):
        load(tmp_path / "x.txt")
    with pytest.raises(FormatError, match="skeleton only"):
        load(DATA / "07.asf")


def test_amc_round_trip_real_clip(tmp_path, walk_amc):
    assert walk_amc.num_frames == 415 and walk_amc.num_channels == 62
    assert walk_amc.skeleton.units_per_metre == pytest.approx(1 / 0.056444, rel=1e-4)
    written = save(walk_amc, tmp_path / "w.amc")
    assert [p.name for p in written] == ["w.asf", "w.amc"]
    back = load(tmp_path / "w.amc")
    assert back.skeleton.isclose(walk_amc.skeleton, atol=1e-5), back.skeleton.difference(walk_amc.skeleton, 1e-5)
    assert back.isclose(walk_amc, atol_degrees=1e-6, atol_units=1e-6)


def test_bvh_round_trip_real_clip(tmp_path, walk_bvh):
    save(walk_bvh, tmp_path / "w.bvh")
    back = load(tmp_path / "w.bvh")
    assert back.isclose(walk_bvh, atol_degrees=1e-6, atol_units=1e-6), back.difference(walk_bvh)


def test_conversion_keeps_every_pose(tmp_path, walk_amc, walk_bvh):
    for motion in (walk_amc, walk_bvh):
        for ext in (".bvh", ".amc"):
            save(motion, tmp_path / f"c{ext}")
            back = load(tmp_path / f"c{ext}")
            names = [n for n in motion.skeleton.names if n in back.skeleton.names]
            a = motion.positions_m()[:, [motion.skeleton.index(n) for n in names]]
            b = back.positions_m()[:, [back.skeleton.index(n) for n in names]]
            assert len(names) >= len(motion.skeleton) - 1  # ASF renames the BVH root to 'root'
            assert np.abs(a - b).max() < 1e-6  # metres


def test_bvh_translations_below_root_cannot_become_asf(tmp_path):
    m = load(write(tmp_path, "a.bvh", SMALL_BVH))
    with pytest.raises(ConversionError, match="'Arm' has translation channels"):
        to_asf_form(m)
    assert load(write(tmp_path, "b.bvh", SMALL_BVH)).isclose(to_bvh_form(m))


def test_amc_errors(tmp_path):
    asf = (DATA / "07.asf").read_text()
    (tmp_path / "07.asf").write_text(asf)
    good = (DATA / "07_03.amc").read_text().split("\n")[:70]
    cases = [
        (lambda ls: [l.replace("lowerback", "lowerbak") for l in ls], "'lowerbak' is not defined in the ASF"),
        (lambda ls: [l if not l.startswith("ltibia") else "ltibia 1 2" for l in ls], "has 2 values, expected 1"),
        (lambda ls: [l if l.strip() != "2" else "3" for l in ls], "frame number 3, expected 2"),
        (lambda ls: [l if not l.startswith("head ") else "head 1 zz 3" for l in ls], "'zz' is not a number"),
        (lambda ls: [l for l in ls if not l.startswith("rfoot")], "has no line for bone 'rfoot'"),
        (lambda ls: [":WHATEVER"] + ls, "unknown AMC keyword"),
    ]
    for edit, message in cases:
        p = tmp_path / "07_01.amc"
        p.write_text("\n".join(edit(list(good))))
        with pytest.raises(FormatError, match=message):
            load(p)


def test_missing_or_mismatched_asf(tmp_path):
    amc = tmp_path / "99_01.amc"
    amc.write_text((DATA / "07_03.amc").read_text())
    with pytest.raises(FormatError, match="no ASF skeleton found"):
        load(amc)
    renamed = tmp_path / "renamed.asf"
    renamed.write_text((DATA / "07.asf").read_text().replace("lhand", "lpalm"))
    with pytest.raises(FormatError, match="'lhand' is not defined in the ASF") as exc:
        load(amc, asf=renamed)
    assert exc.value.line is not None


@pytest.mark.parametrize(
    "edit, message",
    [
        (lambda t: t.replace(":units", ":unitz"), "unknown section ':unitz'"),
        (lambda t: t.replace("length 0.45", "length abc"), "'abc' is not a number"),
        (lambda t: t.replace("dof rx ry rz", "dof rx ry rq", 1), "dof 'rq' is not supported"),
        (lambda t: t.replace("    lfemur ltibia", "    lfemur ltibia lnothing"), "'lnothing' is not defined"),
        (lambda t: t.replace("     direction", "     directoin", 1), "unknown bone keyword"),
    ],
)
def test_asf_errors(tmp_path, edit, message):
    p = tmp_path / "bad.asf"
    p.write_text(edit((DATA / "07.asf").read_text()))
    with pytest.raises(FormatError, match=message) as exc:
        read_asf(p)
    assert exc.value.line is not None or "section" in message


def test_writes_are_atomic(tmp_path, walk_bvh, monkeypatch):
    target = tmp_path / "keep.bvh"
    target.write_text("old contents")

    def boom(*_a, **_k):
        raise RuntimeError("disk full")

    monkeypatch.setattr("mocodec.formats.bvh.format_rows", boom)
    with pytest.raises(RuntimeError):
        save(walk_bvh, target)
    assert target.read_text() == "old contents"
    assert [p.name for p in tmp_path.iterdir()] == ["keep.bvh"]


def test_unit_guess():
    assert guess_units_per_metre(152.7) == 100.0
    assert guess_units_per_metre(1.6) == 1.0
    assert guess_units_per_metre(62.0) == pytest.approx(1 / 0.0254)
    assert guess_units_per_metre(1700.0) == 1000.0

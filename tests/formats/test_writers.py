"""Writers keep columns and joints together whatever the joint order; a written BVH reads back
in its own unit; a glTF's frame rate and duration come from its key times; the stillness
threshold knows float32 noise and says what it dropped."""

from __future__ import annotations

import numpy as np
import pytest

from gltf_builder import GltfBuilder
from mocodec import load, save
from mocodec.formats import nodetree
from mocodec.formats.bvh import bvh_text, guess_units_per_metre, read_bvh
from mocodec.motion import Motion
from mocodec.skeleton import Joint, Skeleton


def _shuffled_motion(seed: int, translations_below_root: bool) -> Motion:
    """A random tree whose joints come parents first but not depth first, every joint with
    its own channel set and Euler order, random motion."""
    rng = np.random.default_rng(seed)
    n = int(rng.integers(6, 14))
    parents = [-1] + [int(rng.integers(0, i)) for i in range(1, n)]
    while _is_depth_first(parents):
        parents = [-1] + [int(rng.integers(0, i)) for i in range(1, n)]
    joints = []
    for i, parent in enumerate(parents):
        order = "".join(rng.permutation(list("XYZ"))[: int(rng.integers(0 if i else 1, 4))])
        channels = [f"{a}rotation" for a in order]
        if i == 0 or (translations_below_root and rng.random() < 0.3):
            channels = ["Xposition", "Yposition", "Zposition", *channels]
        offset = tuple(float(v) for v in rng.uniform(-30, 30, 3)) if i else (0.0, 0.0, 0.0)
        joints.append(Joint(f"j{i}", parent, offset, tuple(channels), order))
    skeleton = Skeleton(tuple(joints), units_per_metre=100.0)
    values = rng.uniform(-80, 80, (12, skeleton.num_channels))
    return Motion(skeleton, 30.0, values)


def _is_depth_first(parents: list[int]) -> bool:
    """Whether each joint's parent is the joint before it or one of that joint's ancestors."""
    for i in range(1, len(parents)):
        chain, node = set(), i - 1
        while node >= 0:
            chain.add(node)
            node = parents[node]
        if parents[i] not in chain:
            return False
    return True


def _positions_by_name(motion: Motion, names) -> np.ndarray:
    sk = motion.skeleton
    return motion.positions()[:, [sk.index(name) for name in names]] / sk.units_per_metre


@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize("ext", [".bvh", ".glb", ".amc"])
def test_a_writer_keeps_every_joints_motion_whatever_the_joint_order(seed, ext, tmp_path):
    if ext == ".glb":
        pytest.importorskip("pygltflib")
    motion = _shuffled_motion(seed, translations_below_root=ext != ".amc")
    save(motion, tmp_path / f"m{ext}")
    back = load(tmp_path / f"m{ext}", fps=30.0 if ext == ".amc" else None)
    expected = motion.positions() / motion.skeleton.units_per_metre
    got = back.positions() / back.skeleton.units_per_metre
    for k, name in enumerate(motion.skeleton.names):
        if k and name in back.skeleton.names:
            assert np.abs(got[:, back.skeleton.index(name)] - expected[:, k]).max() < 1e-6, name
        else:  # the root ('root' in ASF), an end site renamed after its parent: the same path
            assert (np.abs(got - expected[:, k : k + 1]).max(axis=(0, 2)) < 1e-6).any(), name


def test_the_shuffled_skeletons_are_not_depth_first():
    for seed in range(6):
        assert not _is_depth_first(list(_shuffled_motion(seed, True).skeleton.parents))


# ----- units -------------------------------------------------------------------------------------


def test_the_unit_guess_uses_the_span_along_the_bones_not_the_rest_pose():
    assert guess_units_per_metre(236.0) == 100.0  # CMU BVH: fingertip to toe, centimetres
    assert guess_units_per_metre(1.7) == 1.0
    assert guess_units_per_metre(62.0) == pytest.approx(1 / 0.0254)
    assert guess_units_per_metre(1700.0) == 1000.0
    assert guess_units_per_metre(9.0) == 100.0  # fits none: centimetres


def _lying_figure(units_per_metre: float) -> Motion:
    """A 1.6 m figure whose rest pose lies flat (height 0), as some exported rigs do."""
    u = units_per_metre
    joints = [
        Joint("hips", -1, (0, 0, 0), ("Xposition", "Yposition", "Zposition", "Zrotation"), "Z"),
        Joint("head", 0, (0, 0, 0.7 * u), ("Zrotation",), "Z"),
        Joint("head_end", 1, (0, 0, 0.2 * u)),
        Joint("foot", 0, (0, 0, -0.7 * u), ("Zrotation",), "Z"),
    ]
    return Motion(Skeleton(tuple(joints), u), 24.0, np.zeros((3, 6)))


@pytest.mark.parametrize("units", [100.0, 1.0, 1 / 0.0254, 7.0])
def test_a_written_bvh_reads_back_in_its_own_unit(units, tmp_path):
    motion = _lying_figure(units)
    assert motion.skeleton.height() == 0.0
    save(motion, tmp_path / "m.bvh")
    back = read_bvh(tmp_path / "m.bvh")
    assert back.skeleton.span() / back.skeleton.units_per_metre == pytest.approx(1.6)


def test_the_unit_is_stated_only_where_a_reader_would_guess_another():
    assert "# unit" not in bvh_text(_lying_figure(100.0))
    joints = (Joint("a", -1, (0, 0, 0), ("Zrotation",), "Z"), Joint("b", 0, (0, 62, 0)))
    small = Motion(Skeleton(joints, 100.0), 30.0, [[0.0]])  # 0.62 m, or 1.57 m if inches
    text = bvh_text(small)
    assert text.splitlines()[1] == "# unit: 100.0 per metre"
    assert read_bvh_text(text, tmp_name="small").skeleton.units_per_metre == 100.0
    assert read_bvh_text(text.replace("100.0 per", "1000 per"), tmp_name="mm").skeleton.units_per_metre == 1000.0


def read_bvh_text(text: str, tmp_name: str):
    import tempfile
    from pathlib import Path

    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / f"{tmp_name}.bvh"
        path.write_text(text)
        return read_bvh(path)


def test_units_given_override_the_stated_and_the_guessed_unit(tmp_path):
    save(_lying_figure(100.0), tmp_path / "m.bvh")
    assert load(tmp_path / "m.bvh", units_per_metre=39.37).skeleton.units_per_metre == 39.37


def test_a_bvh_in_metres_keeps_a_millionth_of_a_centimetre(tmp_path):
    motion = _lying_figure(1.0)
    motion = motion.with_channels(np.full((3, 6), 0.123456789))
    save(motion, tmp_path / "m.bvh")
    back = read_bvh(tmp_path / "m.bvh")
    assert back.skeleton.units_per_metre == 1.0
    assert np.abs(back.positions() - motion.positions()).max() < 1e-8


def test_bvh_position_channels_hold_the_joints_position_in_place_of_its_offset(tmp_path):
    """As MotionBuilder writes them and Blender reads them: a joint whose position channels equal
    its offset is where its offset puts it, not twice as far."""
    text = (
        "HIERARCHY\nROOT r\n{\n OFFSET 0 0 0\n CHANNELS 3 Xposition Yposition Zposition\n"
        " JOINT a\n {\n  OFFSET 0 10 0\n  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation\n"
        "  End Site\n  {\n   OFFSET 0 5 0\n  }\n }\n}\nMOTION\nFrames: 2\nFrame Time: 0.1\n"
        "0 0 0 0 10 0 0 0 0\n0 0 0 1 12 0 90 0 0\n"
    )
    motion = read_bvh_text(text, tmp_name="mobu")
    assert np.allclose(motion.positions()[0, 1], [0, 10, 0]) and np.allclose(motion.positions()[1, 1], [1, 12, 0])
    assert np.allclose(motion.positions()[1, 2], [-4, 12, 0])  # the end site, turned 90 degrees about Z
    assert bvh_text(motion).endswith(
        "0 0 0 0 10 0 0 0 0\n0 0 0 1 12 0 90 0 0\n".replace(" ", ".000000 ").replace("\n", ".000000\n")
    )


# ----- glTF time -------------------------------------------------------------------------------


def _keyed(tmp_path, times) -> Motion:
    """A two-node glTF whose child turns about Z with keys at ``times``."""
    g = GltfBuilder()
    g.doc["nodes"] = [{"name": "root", "children": [1]}, {"name": "tip", "translation": [0, 1, 0]}]
    angles = np.linspace(0, np.pi / 2, len(times))
    xyzw = np.stack([0 * angles, 0 * angles, np.sin(angles / 2), np.cos(angles / 2)], axis=1)
    g.animation("turn", [(0, "rotation", list(times), xyzw.tolist(), "LINEAR")])
    (tmp_path / "k.glb").write_bytes(g.glb())
    return load(tmp_path / "k.glb")


@pytest.mark.parametrize(
    "times, fps, frames",
    [
        (np.arange(25) / 24.0, 24.0, 25),  # baked at 24 fps
        (np.array([0, 1, 2, 5, 6]) / 60.0, 60.0, 7),  # baked at 60 fps, keys reduced
        (np.array([0.0, 1.25]), 30.4, 39),  # two authored keys: 30 fps, adjusted to end on a frame
        (np.array([0.0, 0.5, 1.0, 5.5]), 30.0, 166),  # keys every 0.5 s: animator's keys, not a grid
        (np.array([0.0, 0.013, 0.05, 0.1]), 30.0, 4),  # irregular times
    ],
)
def test_the_frame_rate_comes_from_a_grid_of_key_times_or_is_30_fps(times, fps, frames, tmp_path):
    motion = _keyed(tmp_path, times)
    assert motion.fps == pytest.approx(fps) and motion.num_frames == frames
    assert motion.time_span == pytest.approx(times[-1] - times[0])


# ----- stillness -------------------------------------------------------------------------------


def _samples(noise_m: float, frames: int = 20, seed: int = 0) -> nodetree.NodeSamples:
    """A 5-joint chain, 0.3 m bones, its root walking, every other offset wobbling by
    ``noise_m`` (metres), as exporters' float32 transforms do."""
    rng = np.random.default_rng(seed)
    n = 5
    position = np.zeros((frames, n, 3))
    position[:, :, 1] = 0.3 * np.arange(n)
    position[:, :, 0] += np.linspace(0, 1, frames)[:, None]
    position[:, 1:] += rng.uniform(-noise_m / 2, noise_m / 2, (frames, n - 1, 3))
    rotation = np.tile([1.0, 0, 0, 0], (frames, n, 1))
    return nodetree.NodeSamples([f"j{i}" for i in range(n)], np.arange(-1, n - 1), position, rotation)


def test_float32_noise_is_no_channel_and_what_it_moves_is_reported():
    motion = nodetree.to_motion(_samples(2e-7), 30.0, 100.0)
    assert motion.skeleton.num_channels == 3  # the root's walk only
    meta = motion.skeleton.metadata
    assert meta["precision_m"] == nodetree.STILL_M and 0 < meta["dropped_m"] <= meta["precision_m"]


def test_motion_above_the_precision_is_kept_exactly():
    samples = _samples(5e-5)
    motion = nodetree.to_motion(samples, 30.0, 100.0)
    assert motion.skeleton.num_channels == 3 + 3 * 4
    assert np.abs(motion.positions() / 100.0 - samples.position).max() < 1e-12


def test_noise_that_adds_up_along_a_chain_is_kept_where_it_would_pass_the_precision():
    samples = _samples(0.9e-6, frames=200)  # each under the precision, a chain of four over it
    motion = nodetree.to_motion(samples, 30.0, 100.0)
    error = np.linalg.norm(motion.positions() / 100.0 - samples.position, axis=2).max()
    assert error <= nodetree.STILL_M and motion.skeleton.metadata["dropped_m"] == pytest.approx(error)
    assert 3 < motion.skeleton.num_channels < 3 + 3 * 4


def test_the_precision_grows_with_the_coordinates_as_float32_steps_do():
    assert nodetree.precision_m(np.array([1.0])) == nodetree.STILL_M
    assert nodetree.precision_m(np.array([100.0])) == pytest.approx(8 * 2.0**-17)

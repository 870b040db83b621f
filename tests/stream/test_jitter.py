"""The receiver-side jitter buffer: bursts and jittered arrivals in, a pose that moves at the
sender's frame rate out."""

from __future__ import annotations

import numpy as np
import pytest

from mocodec.errors import CodecError
from mocodec.stream.jitter import SLEW, JitterBuffer


def _ramp(frames: int) -> np.ndarray:
    """Frame f's channels are (f, 2 f): what frame plays is readable from the pose."""
    f = np.arange(frames, dtype=np.float64)
    return np.stack((f, 2 * f), axis=1)


def test_jittered_bursts_play_out_smoothly_at_the_frame_rate():
    fps, packet, rng = 120.0, 6, np.random.default_rng(5)
    frames = _ramp(1200)
    buf = JitterBuffer(fps, 2, delay_s=0.1)
    arrivals = [(k, (k + packet) / fps + rng.uniform(0.0, 0.06)) for k in range(0, len(frames), packet)]
    shown, pending = [], sorted(arrivals, key=lambda a: a[1])
    display = np.arange(0.3, 9.0, 1 / 90.0)  # a 90 Hz display
    for now in display:
        while pending and pending[0][1] <= now:
            k, t = pending.pop(0)
            buf.push(frames[k : k + packet], k, t)
        shown.append(buf.pose(now)[0])
    steps = np.diff(shown)
    assert np.allclose(steps, fps / 90.0, rtol=SLEW * 1.001)  # the played frame advances evenly
    assert buf.late == 0  # 60 ms of jitter under a 100 ms delay


def test_a_late_burst_lengthens_the_delay_and_early_ones_shrink_it():
    buf = JitterBuffer(30.0, 2, delay_s=0.1)
    frames = _ramp(900)
    buf.push(frames[:1], 0, 1.0)
    start = buf.origin
    buf.push(frames[1:2], 1, 1.0 + 1 / 30.0 + 0.2)  # 200 ms late: 100 ms after it should have played
    assert buf.late == 1 and buf.origin == pytest.approx(start + 0.1)
    late_origin = buf.origin
    for f in range(2, 900):  # then every frame on time, shown as it comes: back to the delay asked for
        buf.push(frames[f : f + 1], f, 1.0 + f / 30.0)
        buf.pose(1.0 + f / 30.0)
    assert buf.origin == pytest.approx(start, abs=1e-6) and late_origin - buf.origin == pytest.approx(0.1)


def test_interpolation_between_frames_holding_past_the_end_and_over_gaps():
    buf = JitterBuffer(10.0, 2, delay_s=0.0)
    buf.push(_ramp(3), 0, 0.2)  # frames 0-2; frame 2 plays at 0.2 s, so frame 0 at 0.0
    assert np.allclose(buf.pose(0.05), [0.5, 1.0])
    assert np.allclose(buf.pose(5.0), [2.0, 4.0])  # held
    buf.push(_ramp(8)[6:8], 6, 0.55)  # frames 3-5 never came: held over the gap
    assert np.allclose(buf.pose(0.45), [2.0, 4.0]) and np.allclose(buf.pose(0.7), [7.0, 14.0])


def test_nothing_to_show_before_the_first_frame_and_bad_settings_refused():
    assert JitterBuffer(30.0, 2).pose(1.0) is None
    with pytest.raises(CodecError):
        JitterBuffer(0.0, 2)


def test_a_watcher_plays_each_stream_through_its_jitter_buffer(walk_bvh):
    from mocodec.codecs import get_codec
    from mocodec.stream.client import Watcher
    from mocodec.stream.live import stream_clip
    from mocodec.stream.packets import pack_batch

    watcher = Watcher()
    packets = stream_clip(walk_bvh, get_codec("kinwave-live"))
    assert watcher.pose(0) is None
    watcher.take(pack_batch([p.to_bytes() for p in packets]))  # all at once: a burst
    buffer = watcher.jitter[0]
    now = buffer.origin + 200 / walk_bvh.fps  # when frame 200 plays
    pose = watcher.pose(0, now)
    decoded = watcher.motion(0).channels
    assert pose.shape == (walk_bvh.skeleton.num_channels,) and np.allclose(pose, decoded[200])

"""Rate control on a real clip with a simple lossy codec: ratio and bit-rate targets within
2%, error bounds met on the decoded output."""

from __future__ import annotations

import numpy as np
import pytest

import stepcodec  # noqa: F401
from mocodec import moc, ratecontrol
from mocodec.codecs import get_codec
from mocodec.errors import CodecError
from mocodec.metrics import compare


@pytest.mark.parametrize("ratio", [4.0, 8.0, 15.0])
def test_ratio_target_within_two_percent(walk_amc, ratio):
    m = ratecontrol.tune(get_codec("test-step"), walk_amc, "ratio", ratio)
    assert ratio <= m.ratio <= ratio * 1.02
    assert m.ratio == pytest.approx(walk_amc.raw_bits / 8 / len(m.data))


def test_bitrate_target(walk_amc):
    m = ratecontrol.tune(get_codec("test-step"), walk_amc, "bitrate", 20000.0)
    assert 20000 * 0.98 <= m.bitrate <= 20000


@pytest.mark.parametrize("bound", [0.1, 0.5, 2.0])
def test_max_error_bound_holds_on_the_decoded_file(walk_amc, bound):
    m = ratecontrol.tune(get_codec("test-step"), walk_amc, "max_error_cm", bound)
    decoded = moc.unpack(m.data)
    assert compare(walk_amc, decoded).joints.max <= bound
    # and it does not waste bits: the bisection's last failing step is within 0.1% of it, so
    # half the step would cost clearly more
    finer = ratecontrol.measure(m.codec.with_knob("step", m.codec.config["step"] / 2), walk_amc)
    assert len(finer.data) > 1.05 * len(m.data)


def test_mean_error_and_psnr_targets(walk_amc):
    m = ratecontrol.tune(get_codec("test-step"), walk_amc, "mean_error_cm", 0.3)
    assert m.mean_error_cm <= 0.3
    p = ratecontrol.tune(get_codec("test-step"), walk_amc, "psnr", 50.0)
    assert p.psnr >= 50.0


def test_unreachable_targets_say_so(walk_amc):
    with pytest.raises(CodecError, match="cannot reach"):
        ratecontrol.tune(get_codec("test-step"), walk_amc, "max_error_cm", 1e-9)
    with pytest.raises(CodecError, match="no quality knob"):
        ratecontrol.tune(get_codec("lossless"), walk_amc, "ratio", 50)
    assert ratecontrol.tune(get_codec("lossless"), walk_amc, "max_error_cm", 0.1).max_error_cm == 0
    with pytest.raises(CodecError, match="unknown target"):
        ratecontrol.tune(get_codec("test-step"), walk_amc, "speed", 1)
    with pytest.raises(CodecError, match="positive"):
        ratecontrol.tune(get_codec("test-step"), walk_amc, "ratio", np.nan)

"""``kinwave-live`` by job: :mod:`.codec` (the codec, its knobs and its stream's tables),
:mod:`.syntax` (the bitstream), :mod:`.predict` (the prediction both ends share),
:mod:`.encoder` and :mod:`.decoder`."""

from mocodec.codecs.kinwave.live.codec import KinwaveLiveCodec, base_codes, layer_bounds
from mocodec.codecs.kinwave.live.syntax import DELAY_S, packet_frames

__all__ = ["DELAY_S", "KinwaveLiveCodec", "base_codes", "layer_bounds", "packet_frames"]

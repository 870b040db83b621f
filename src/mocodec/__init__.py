"""mocodec: coding (compression) of human motion capture.

The data model (:class:`Skeleton`, :class:`Motion`), BVH and ASF/AMC files (:func:`load`,
:func:`save`), forward kinematics and rotations, the built-in human model of the thesis, the
codecs (:func:`get_codec`) and .moc files (:mod:`mocodec.moc`: ``encode``, ``decode``).
"""

from mocodec import moc
from mocodec.codecs import codec_ids, get_codec
from mocodec.errors import CodecError, ConversionError, CorruptStreamError, FormatError, MocodecError
from mocodec.formats import load, save
from mocodec.human import human_model
from mocodec.motion import Motion
from mocodec.skeleton import BODY_PARTS, Joint, Skeleton

__version__ = "0.1.0"

__all__ = ["Skeleton", "Joint", "Motion", "load", "save", "human_model", "BODY_PARTS", "get_codec", "codec_ids",
           "moc", "MocodecError", "FormatError", "ConversionError", "CodecError", "CorruptStreamError",
           "__version__"]

"""mocodec: coding (compression) of human motion capture.

The data model (:class:`Skeleton`, :class:`Motion`), BVH and ASF/AMC files (:func:`load`,
:func:`save`), forward kinematics and rotations, and the built-in human model of the thesis.
"""

from mocodec.errors import ConversionError, FormatError, MocodecError
from mocodec.formats import load, save
from mocodec.human import human_model
from mocodec.motion import Motion
from mocodec.skeleton import BODY_PARTS, Joint, Skeleton

__version__ = "0.1.0"

__all__ = ["Skeleton", "Joint", "Motion", "load", "save", "human_model", "BODY_PARTS",
           "MocodecError", "FormatError", "ConversionError", "__version__"]

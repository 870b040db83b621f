"""Error measures: the waveform, group and visual measures of 000 ch. 6 and pose measures in
centimetres. :func:`compare` computes all of them for an original/decoded pair."""

from mocodec.metrics.compare import Comparison, MismatchError, check_pair, compare
from mocodec.metrics.groups import (
    configuration_error,
    group_channels,
    group_joints,
    joint_position_error,
    max_vector_error,
    vector_error,
)
from mocodec.metrics.natural import derivative_outliers, limit_violations, naturalness
from mocodec.metrics.pose import foot_sliding, jerk, joint_errors, shell_errors
from mocodec.metrics.visual import BAND_EDGES_HZ, BAND_WEIGHTS, band_split, visual_errors, weighted_error
from mocodec.metrics.waveform import DofErrors, channel_error, dof_errors

__all__ = [
    "Comparison",
    "MismatchError",
    "check_pair",
    "compare",
    "configuration_error",
    "group_channels",
    "group_joints",
    "joint_position_error",
    "max_vector_error",
    "vector_error",
    "derivative_outliers",
    "limit_violations",
    "naturalness",
    "foot_sliding",
    "jerk",
    "joint_errors",
    "shell_errors",
    "BAND_EDGES_HZ",
    "BAND_WEIGHTS",
    "band_split",
    "visual_errors",
    "weighted_error",
    "DofErrors",
    "channel_error",
    "dof_errors",
]

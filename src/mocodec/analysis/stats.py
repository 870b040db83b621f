"""Spatial content of a motion (000 §5.2.2): per-DOF range, mean and standard deviation
(tables 5-2, 5-3), the usable resolution in bits given the sensor noise ((5-1) to (5-3),
table 5-4) and the raw bit rate it implies.

The thesis writes the usable bits of a DOF as the hardware word length minus the bits lost
to noise, N_h = log2(2^B sigma / FS), minus the bits the motion never uses, N_r =
log2(FS / R): N = B - N_h - N_r, which is log2(R / sigma) while the noise is above one
hardware step (FS is the full scale: 6 m for the +-3 m tracker, 360 degrees, 70 degrees of
finger flexion; B = 16 bits, 8 for the glove). Its example body needs 345 + 168 bits a frame,
15390 bit/s at 30 Hz.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mocodec.motion import Motion

POSITION_FULL_SCALE_CM = 600.0  # +-3 m tracker range
ANGLE_FULL_SCALE_DEG = 360.0
HARDWARE_BITS = 16


@dataclass(frozen=True)
class DofStatistics:
    names: tuple[str, ...]
    minimum: np.ndarray
    maximum: np.ndarray
    mean: np.ndarray  # (5-4)
    std: np.ndarray  # square root of (5-5)

    @property
    def range(self) -> np.ndarray:
        return self.maximum - self.minimum


def dof_statistics(motion: Motion) -> DofStatistics:
    """Tables 5-2 and 5-3: min, max, range, mean and standard deviation of every DOF (degrees,
    translations in skeleton units)."""
    ch = motion.channels
    return DofStatistics(motion.skeleton.channel_names, ch.min(axis=0), ch.max(axis=0), ch.mean(axis=0), ch.std(axis=0))


def usable_bits(
    value_range: np.ndarray, noise_std: float | np.ndarray, full_scale: float, hardware_bits: int = HARDWARE_BITS
) -> np.ndarray:
    """(5-1) to (5-3): B - log2(2^B sigma / FS) - log2(FS / R), rounded down, never below 0.
    Noise below one hardware step costs nothing (N_h >= 0)."""
    value_range = np.asarray(value_range, dtype=np.float64)
    noise_bits = np.maximum(0.0, np.log2(2.0**hardware_bits * np.asarray(noise_std, dtype=np.float64) / full_scale))
    with np.errstate(divide="ignore"):
        range_bits = np.log2(full_scale / value_range)
    bits = hardware_bits - noise_bits - np.maximum(range_bits, 0.0)
    return np.floor(np.clip(np.nan_to_num(bits, neginf=0.0), 0, hardware_bits)).astype(int)


def resolution_bits(motion: Motion, noise_deg: float, noise_cm: float) -> np.ndarray:
    """Usable bits of every DOF of ``motion`` for the given sensor noise (standard deviations)."""
    sk = motion.skeleton
    rng = np.ptp(motion.channels, axis=0) if motion.num_frames else np.zeros(sk.num_channels)
    rot = sk.rotation_mask
    bits = np.zeros(sk.num_channels, dtype=int)
    bits[rot] = usable_bits(rng[rot], noise_deg, ANGLE_FULL_SCALE_DEG)
    bits[~rot] = usable_bits(rng[~rot] * 100.0 / sk.units_per_metre, noise_cm, POSITION_FULL_SCALE_CM)
    return bits


def raw_bit_rate(bits_per_dof: np.ndarray, fps: float) -> float:
    """Bits per second to send every DOF at its usable resolution, every frame (§5.2.2)."""
    return float(np.sum(bits_per_dof) * fps)

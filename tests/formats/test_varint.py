"""Varints (formats/varint.py): one at a time and in bulk, the same bytes."""

from __future__ import annotations

import numpy as np
import pytest

from mocodec.formats import varint


def test_bulk_varints_are_the_single_ones_back_to_back():
    rng = np.random.default_rng(5)
    edges = [0, 1, 127, 128, 16383, 16384, (1 << 21) - 1, 1 << 21, (1 << 28) - 1]
    values = np.concatenate([rng.integers(0, 1 << 28, 500), edges])
    data = varint.pack_array(values)
    assert data == b"".join(varint.pack(int(v)) for v in values)
    back, end = varint.unpack_array(data + b"tail", 0, len(values))
    assert back.tolist() == values.tolist() and end == len(data)
    assert varint.pack_array(np.zeros(0, dtype=np.int64)) == b"" and varint.unpack_array(b"", 0, 0)[1] == 0


def test_bulk_varints_refuse_what_they_cannot_hold():
    with pytest.raises(ValueError, match="outside"):
        varint.pack_array(np.array([1 << 28]))
    with pytest.raises(ValueError, match="outside"):
        varint.pack_array(np.array([-1]))
    with pytest.raises(ValueError, match="ends inside"):
        varint.unpack_array(b"\x01\x80", 0, 2)
    with pytest.raises(ValueError, match="longer than 4"):
        varint.unpack_array(b"\x80\x80\x80\x80\x01\x00", 0, 1)

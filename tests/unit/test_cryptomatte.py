"""Cryptomatte's encoding (core/cryptomatte.py) against the specification's own values."""
import json
import struct

import numpy as np
import pytest
from hypothesis import given, strategies as st

from csm_engine.core import cryptomatte


@pytest.mark.parametrize("name,expected", [
    # The Cryptomatte specification's manifest example, and MurmurHash3's published
    # x86_32 vectors (seed 0).
    ("bunny", 0x13851A76), ("default", 0x42C9679F), ("", 0x00000000),
    ("test", 0xBA6BD213), ("Hello, world!", 0xC0363E43),
])
def test_murmurhash3_matches_the_reference(name, expected):
    assert cryptomatte.murmurhash3_32(name) == expected


def test_names_are_hashed_as_utf8():
    assert cryptomatte.murmurhash3_32("Würfel") == \
        cryptomatte.murmurhash3_32("Würfel".encode("utf-8"))


@given(st.integers(min_value=0, max_value=2**32 - 1))
def test_ids_are_finite_normal_floats_keeping_sign_and_mantissa(value):
    as_float = cryptomatte.hash_to_float(value)
    bits = struct.unpack("<I", struct.pack("<f", as_float))[0]
    exponent = (bits >> 23) & 0xFF
    assert 1 <= exponent <= 254 and np.isfinite(as_float)
    assert bits & 0x807FFFFF == value & 0x807FFFFF
    if 1 <= (value >> 23) & 0xFF <= 254:
        assert bits == value          # a hash that is already a normal float is kept


def test_metadata_keys_are_blenders():
    data = cryptomatte.metadata("ViewLayer", "OBJECT", ["Cube", "Suzanne", "Cube"])
    # Blender keys a layer by the first 7 hex digits of its name's hash.
    prefix = f"cryptomatte/{cryptomatte.murmurhash3_32('ViewLayer.CryptoObject'):08x}"[:19]
    assert data[prefix + "/name"] == "ViewLayer.CryptoObject"
    assert data[prefix + "/hash"] == "MurmurHash3_32"
    assert data[prefix + "/conversion"] == "uint32_to_float32"
    manifest = json.loads(data[prefix + "/manifest"])
    assert manifest == {"Cube": f"{cryptomatte.murmurhash3_32('Cube'):08x}",
                        "Suzanne": f"{cryptomatte.murmurhash3_32('Suzanne'):08x}"}


def test_rank_coverage_orders_ids_by_their_share_of_the_samples():
    a, b, c = (cryptomatte.name_id(n) for n in ("a", "b", "c"))
    # One pixel, four samples: a twice, b once, background once (weights sum to 1).
    ids = np.array([a, b, a, 0.0], dtype=np.float32).reshape(4, 1, 1)
    ranked, coverage = cryptomatte.rank_coverage(ids, [0.25, 0.25, 0.25, 0.25], 3)
    assert ranked[0, 0].tolist() == [a, b, 0.0]
    assert coverage[0, 0].tolist() == [0.5, 0.25, 0.0]
    # Weights count, not sample numbers; c alone covers a pixel fully.
    ids = np.array([[[a, c]], [[b, c]]], dtype=np.float32)
    ranked, coverage = cryptomatte.rank_coverage(ids, [0.2, 0.8], 2)
    assert ranked[0, 0].tolist() == [b, a] and np.allclose(coverage[0, 0], [0.8, 0.2])
    assert ranked[0, 1].tolist() == [c, 0.0] and np.allclose(coverage[0, 1], [1.0, 0.0])


def test_levels_pack_two_to_a_pass():
    ranked = np.arange(1, 6, dtype=np.float32).reshape(1, 1, 5)
    coverage = ranked / 10
    passes = cryptomatte.pack_levels(ranked, coverage)
    assert len(passes) == cryptomatte.pass_count(5) == 3
    assert passes[0][0, 0].tolist() == pytest.approx([1, 0.1, 2, 0.2])
    assert passes[2][0, 0].tolist() == pytest.approx([5, 0.5, 0, 0])


def test_one_sample_gives_each_pixel_its_id_wholly():
    a = cryptomatte.name_id("a")
    ids = np.array([[[a, 0.0]]], dtype=np.float32)
    ranked, coverage = cryptomatte.rank_coverage(ids, [1.0], 2)
    assert ranked[0].tolist() == [[a, 0.0], [0.0, 0.0]]
    assert coverage[0].tolist() == [[1.0, 0.0], [0.0, 0.0]]

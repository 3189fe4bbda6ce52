"""Cryptomatte as Blender writes it: names to IDs, per-pixel rank/coverage, metadata.

Owns the encoding the Cryptomatte specification (Psyop) fixes and Blender's compositor
reads: an object's, material's or asset's name is hashed with MurmurHash3 (x86, 32 bit,
seed 0) and the hash becomes a float32 by its bits, with the exponent kept off 0 and 255 so
no ID is a denormal, an infinity or a NaN (``name_id``); a pixel's IDs are ranked by the
share of its samples they cover (``rank_coverage``) and packed two to an RGBA pass
(``pack_levels``: CryptoObject00 holds rank 0 and 1 as id, coverage, id, coverage); the
render result carries, per layer, ``cryptomatte/<7 hex digits of the layer name's
hash>/name|hash|conversion|manifest`` (``metadata``), the manifest being a JSON object of
name -> 8 hex digits. Blender's Cryptomatte node hashes the names the user types, so the
IDs alone isolate an object; the manifest lets its picker show names. numpy only.
"""

import json
import math
import struct
from types import MappingProxyType

import numpy as np

# The three layers Blender offers (View Layer > Passes > Cryptomatte) and their pass names.
LAYER_PASS_NAMES = MappingProxyType({"OBJECT": "CryptoObject", "MATERIAL": "CryptoMaterial",
                                     "ASSET": "CryptoAsset"})
_MASK32 = 0xFFFFFFFF


def murmurhash3_32(data, seed=0):
    """MurmurHash3 x86_32 of ``data`` (bytes, or str as UTF-8), as an int in 0 .. 2^32-1."""
    if isinstance(data, str):
        data = data.encode("utf-8")
    c1, c2 = 0xCC9E2D51, 0x1B873593
    h = seed & _MASK32
    whole = len(data) // 4 * 4
    for (k,) in struct.iter_unpack("<I", data[:whole]):
        k = (k * c1) & _MASK32
        k = ((k << 15) | (k >> 17)) & _MASK32
        k = (k * c2) & _MASK32
        h ^= k
        h = ((h << 13) | (h >> 19)) & _MASK32
        h = (h * 5 + 0xE6546B64) & _MASK32
    tail = data[whole:]
    if tail:
        k = int.from_bytes(tail, "little")
        k = (k * c1) & _MASK32
        k = ((k << 15) | (k >> 17)) & _MASK32
        k = (k * c2) & _MASK32
        h ^= k
    h ^= len(data)
    h ^= h >> 16
    h = (h * 0x85EBCA6B) & _MASK32
    h ^= h >> 13
    h = (h * 0xC2B2AE35) & _MASK32
    h ^= h >> 16
    return h


def hash_to_float(value):
    """The float32 a 32-bit hash is stored as: its bits, with the exponent clamped to
    1..254 (the specification's ``uint32_to_float32``)."""
    exponent = min(max((value >> 23) & 0xFF, 1), 254)
    bits = (value & 0x807FFFFF) | (exponent << 23)
    return float(np.frombuffer(struct.pack("<I", bits), dtype=np.float32)[0])


def name_id(name):
    """The float ID of a name (an object's, material's or asset's)."""
    return hash_to_float(murmurhash3_32(name))


def manifest(names):
    """The manifest: a JSON object of name -> 8 lower-case hex digits of its hash."""
    return json.dumps({name: f"{murmurhash3_32(name):08x}" for name in sorted(set(names))},
                      ensure_ascii=False, separators=(",", ":"))


def layer_name(view_layer, kind):
    """The Cryptomatte layer's name, e.g. "ViewLayer.CryptoObject" for kind "OBJECT"."""
    return f"{view_layer}.{LAYER_PASS_NAMES[kind]}"


def metadata(view_layer, kind, names):
    """The render result's metadata of one layer, as Blender stores it: key -> value."""
    layer = layer_name(view_layer, kind)
    prefix = f"cryptomatte/{murmurhash3_32(layer):08x}"[:len("cryptomatte/") + 7]
    return {f"{prefix}/name": layer, f"{prefix}/hash": "MurmurHash3_32",
            f"{prefix}/conversion": "uint32_to_float32",
            f"{prefix}/manifest": manifest(names)}


def pass_count(levels):
    """How many RGBA passes hold ``levels`` ranks (two per pass)."""
    return max(int(math.ceil(levels / 2)), 1)


def rank_coverage(ids, weights, levels):
    """Rank each pixel's IDs by coverage. ``ids``: (S, H, W) float32, one ID per sample and
    pixel (0: no surface, never ranked); ``weights``: (S,) sample weights (the pixel
    filter's). Returns ((H, W, levels) IDs, (H, W, levels) coverages), each pixel's IDs by
    coverage, largest first; a coverage is the ID's share of the total weight; unused ranks
    are 0, 0."""
    ids = np.asarray(ids, dtype=np.float32)
    samples, height, width = ids.shape
    if samples == 1:
        # One sample: each pixel is wholly its one ID (the common render without AA).
        out_ids = np.zeros((height, width, levels), dtype=np.float32)
        out_cov = np.zeros((height, width, levels), dtype=np.float32)
        out_ids[..., 0] = ids[0]
        out_cov[..., 0] = ids[0] != 0.0
        return out_ids, out_cov
    weights = np.asarray(weights, dtype=np.float64).reshape(samples, 1)
    flat = ids.reshape(samples, -1)
    # Equal IDs become neighbours; each run's weights are summed at its last sample.
    order = np.argsort(flat, axis=0, kind="stable")
    sorted_ids = np.take_along_axis(flat, order, axis=0)
    sorted_weights = np.broadcast_to(weights, flat.shape)[order, np.arange(flat.shape[1])]
    running = np.cumsum(sorted_weights, axis=0)
    starts = np.ones(flat.shape, dtype=bool)
    starts[1:] = sorted_ids[1:] != sorted_ids[:-1]
    ends = np.ones(flat.shape, dtype=bool)
    ends[:-1] = starts[1:]
    # Weights are positive, so the running sum before each run start only grows.
    before = np.maximum.accumulate(np.where(starts, running - sorted_weights, 0.0), axis=0)
    totals = np.where(ends & (sorted_ids != 0.0), running - before, 0.0)
    total_weight = float(weights.sum()) or 1.0
    rank = np.argsort(-totals, axis=0, kind="stable")[:levels]
    out_ids = np.take_along_axis(sorted_ids, rank, axis=0)
    out_cov = np.take_along_axis(totals, rank, axis=0) / total_weight
    out_ids = np.where(out_cov > 0.0, out_ids, 0.0)
    if len(rank) < levels:
        pad = ((0, levels - len(rank)), (0, 0))
        out_ids, out_cov = np.pad(out_ids, pad), np.pad(out_cov, pad)
    shape = (height, width, levels)
    return (np.moveaxis(out_ids, 0, -1).reshape(shape).astype(np.float32),
            np.moveaxis(out_cov, 0, -1).reshape(shape).astype(np.float32))


def pack_levels(ranked_ids, coverages):
    """The RGBA passes (list of (H, W, 4) float32) of ranked IDs and coverages: pass k
    holds ranks 2k and 2k+1 as (id, coverage, id, coverage)."""
    levels = ranked_ids.shape[-1]
    passes = []
    for k in range(pass_count(levels)):
        rgba = np.zeros(ranked_ids.shape[:2] + (4,), dtype=np.float32)
        for slot in range(2):
            rank = 2 * k + slot
            if rank < levels:
                rgba[..., 2 * slot] = ranked_ids[..., rank]
                rgba[..., 2 * slot + 1] = coverages[..., rank]
        passes.append(rgba)
    return passes

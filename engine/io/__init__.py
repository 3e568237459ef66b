"""Input and output: the only place the engine touches files (BVH, video, results)."""

from engine.io.bvh import (
    BvhFile,
    Reference,
    load_reference,
    read_bvh,
    resample,
    resample_reference,
    sample_at,
    sample_reference,
    write_bvh,
)

__all__ = [
    "BvhFile",
    "Reference",
    "load_reference",
    "read_bvh",
    "resample",
    "resample_reference",
    "sample_at",
    "sample_reference",
    "write_bvh",
]

"""Write MCAP with every integrity record the format offers (schemas/README.md).

The recorder of sessions and evaluations (:mod:`pipeline.rig.recorder`) and
``pipeline viz`` share these settings, so a file armsig writes is one the reader
(:mod:`pipeline.contract.mcap_read`) can check end to end.
"""

from __future__ import annotations

import json
from typing import IO, Any

from mcap.writer import CompressionType, IndexType, Writer

#: One encoder for every message: ``json.dumps`` with these arguments builds a new
#: ``JSONEncoder`` per call (the same bytes; 100,000-row imports write 200,000 messages).
_ENCODER = json.JSONEncoder(separators=(",", ":"), allow_nan=False)


def json_bytes(payload: Any) -> bytes:
    """A message's data: compact JSON; NaN and Infinity, which are not JSON, raise."""
    return _ENCODER.encode(payload).encode()


def checked_writer(fh: IO[bytes], profile: str, library: str) -> Writer:
    """A started MCAP writer: zstd chunks of 1 MiB, chunk, message and metadata indexes,
    chunk and summary CRCs, and the data section's CRC in ``DataEnd``."""
    writer = Writer(
        fh,  # type: ignore[arg-type]
        compression=CompressionType.ZSTD,
        chunk_size=1 << 20,
        index_types=IndexType.ALL,
        enable_crcs=True,
        enable_data_crcs=True,
    )
    writer.start(profile=profile, library=library)
    return writer

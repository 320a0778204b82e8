"""The recorded-content digest: MCAP metadata ``armsig.content`` (schemas/README.md).

SHA-256 over the sorted SHA-256 digests of ``topic + NUL + data`` of every message,
with the message count of every topic. Log times, publish times, sequence numbers,
channel ids and the order of the messages in the file are left out: re-ordering or
re-timing messages is not an edit, changing a byte of any message is.

Also the SHA-256 of a whole file's bytes (:func:`file_sha256`), the content hash of a
recording or an imported file.
"""

from __future__ import annotations

import hashlib
from collections import Counter
from collections.abc import Iterable
from pathlib import Path

DIGEST_NAME = "armsig.content"
ALGORITHM = "sha256(sorted sha256(topic NUL data))"
COUNT_PREFIX = "count:"


def content_digest(messages: Iterable[tuple[str, bytes]]) -> dict[str, str]:
    """The ``armsig.content`` metadata of messages ``(topic, data)``, in any order."""
    counts: Counter[str] = Counter()
    digests = []
    for topic, data in messages:
        counts[topic] += 1
        digests.append(hashlib.sha256(topic.encode() + b"\0" + data).digest())
    total = hashlib.sha256(b"".join(sorted(digests))).hexdigest()
    out = {"algorithm": ALGORITHM, "sha256": total}
    out.update({f"{COUNT_PREFIX}{t}": str(n) for t, n in sorted(counts.items())})
    return out


def file_sha256(path: Path) -> str:
    """Content hash of a file (hex)."""
    h = hashlib.sha256()
    with path.open("rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()

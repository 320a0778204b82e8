"""Seeded mutations of a session recording, and what ``identify`` makes of each.

Each mutation is identified on a copy of the recording in its own session folder. The
outcome of a run is one of:

- ``refused``: a one-line :class:`~pipeline.errors.ArmsigError` (the CLI's exit 1);
- ``same``: a signature whose tool positions differ from the original's by at most
  :data:`SAME_CM` over :data:`CONFIGURATIONS` random configurations;
- a failure: ``traceback`` (any other exception), ``multiline`` (an error message of more
  than one line), ``hang`` (no answer within :data:`TIMEOUT_S`), ``changed`` (exit 0 with a
  signature that differs by more than :data:`SAME_CM`), or ``reordered`` (a harmless
  mutation, below, whose signature is not bit-for-bit the original's).

The rule for harmless mutations: a mutation is *harmless* when it leaves the multiset of
``(topic, message data)`` unchanged: log times, publish times, sequence numbers, the file's
layout. Those must give the original signature bit for bit (the pipeline joins channels by
their keys, never by time) or be refused. Every other mutation changes what was measured or
described, and must be refused or change nothing (<= 1e-9 cm).

``make fuzz`` runs the acceptance numbers of issue 13 on robot3 (500 byte-level and 200
JSON-level mutations); ``tests/test_fuzz.py`` runs a time-bounded sample on a small
committed recording in ``make test``.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import shutil
import signal
import sys
import tempfile
import time
from collections import Counter
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

SAME_CM = 1e-9  # issue 13: "differing from the original by more than 1e-9 cm"
CONFIGURATIONS = 200
TIMEOUT_S = 60.0  # a small recording identifies in well under a second
FAILURES = ("traceback", "multiline", "hang", "changed", "reordered")

#: JSON values a field is replaced with (the mutation keeps the file's integrity records).
BAD_VALUES: tuple[Any, ...] = (
    math.nan,
    math.inf,
    -math.inf,
    0,
    -1,
    -123.4,
    1e300,
    "12.5",
    "tool",
    True,
    False,
    None,
    [],
    {},
    [1, 2],
    99,
    0.5,
)


@dataclass(frozen=True)
class Mutation:
    """A mutated recording: its bytes, a label, and whether it is harmless (module docstring)."""

    label: str
    data: bytes
    harmless: bool


# --------------------------------------------------------------------------- byte level


def byte_mutation(original: bytes, rng: np.random.Generator) -> Mutation:
    """One random byte-level mutation: flip, truncation, splice, zeroed block or deletion."""
    n = len(original)
    kind = rng.choice(["flip", "flip", "flip", "truncate", "splice", "zero", "delete", "insert"])
    buf = bytearray(original)
    if kind == "flip":
        at = int(rng.integers(n))
        buf[at] ^= int(rng.integers(1, 256))
        label = f"flip@{at}"
    elif kind == "truncate":
        at = int(rng.integers(n))
        buf = buf[:at]
        label = f"truncate@{at}"
    elif kind == "splice":
        size = int(rng.integers(1, 256))
        src, dst = (int(v) for v in rng.integers(0, max(1, n - size), 2))
        buf[dst : dst + size] = original[src : src + size]
        label = f"splice{size}@{src}->{dst}"
    elif kind == "zero":
        size = int(rng.integers(1, 64))
        at = int(rng.integers(0, max(1, n - size)))
        buf[at : at + size] = bytes(size)
        label = f"zero{size}@{at}"
    elif kind == "delete":
        size = int(rng.integers(1, 64))
        at = int(rng.integers(0, max(1, n - size)))
        del buf[at : at + size]
        label = f"delete{size}@{at}"
    else:
        size = int(rng.integers(1, 64))
        at = int(rng.integers(n))
        buf[at:at] = rng.integers(0, 256, size, dtype=np.uint8).tobytes()
        label = f"insert{size}@{at}"
    data = bytes(buf)
    return Mutation(label, data, harmless=data == original)


# --------------------------------------------------------------------------- JSON level


@dataclass
class _Record:
    topic: str
    log_time: int
    publish_time: int
    sequence: int
    data: bytes


@dataclass
class _Parsed:
    """The records of a recording, enough to write it back (schemas, channels, metadata)."""

    profile: str
    library: str
    schemas: dict[int, tuple[str, str, bytes]]  # id -> name, encoding, data
    channels: dict[str, tuple[int, str, dict[str, str]]]  # topic -> schema id, encoding, meta
    metadata: list[tuple[str, dict[str, str]]]
    messages: list[_Record]


def parse(data: bytes) -> _Parsed:
    """Every record of an MCAP file that a rewrite needs (read with the mcap package)."""
    import io

    from mcap.reader import make_reader

    reader = make_reader(io.BytesIO(data))
    header = reader.get_header()
    summary = reader.get_summary()
    assert summary is not None
    schemas = {s.id: (s.name, s.encoding, s.data) for s in summary.schemas.values()}
    channels = {
        c.topic: (c.schema_id, c.message_encoding, dict(c.metadata))
        for c in summary.channels.values()
    }
    metadata = [(m.name, dict(m.metadata)) for m in reader.iter_metadata()]
    messages = [
        _Record(ch.topic, m.log_time, m.publish_time, m.sequence, m.data)
        for _, ch, m in reader.iter_messages(log_time_order=False)
    ]
    return _Parsed(header.profile, header.library, schemas, channels, metadata, messages)


def unparse(p: _Parsed) -> bytes:
    """Write the records back with the mcap writer (fresh CRCs and indexes, same metadata)."""
    import io

    from mcap.writer import CompressionType, Writer

    out = io.BytesIO()
    w = Writer(out, compression=CompressionType.ZSTD, enable_data_crcs=True)
    w.start(profile=p.profile, library=p.library)
    sid = {k: w.register_schema(name, enc, data) for k, (name, enc, data) in p.schemas.items()}
    cid = {
        topic: w.register_channel(topic, enc, sid.get(schema_id, 0), meta)
        for topic, (schema_id, enc, meta) in p.channels.items()
    }
    for name, meta in p.metadata:
        w.add_metadata(name, meta)
    for m in sorted(p.messages, key=lambda r: r.log_time):
        w.add_message(cid[m.topic], m.log_time, m.data, m.publish_time, m.sequence)
    w.finish()
    return out.getvalue()


def _leaves(value: Any, path: tuple[Any, ...] = ()) -> Iterator[tuple[Any, ...]]:
    """Paths of every value in a JSON document (containers included, root excluded)."""
    if path:
        yield path
    if isinstance(value, dict):
        for k, v in value.items():
            yield from _leaves(v, (*path, k))
    elif isinstance(value, list):
        for k, v in enumerate(value):
            yield from _leaves(v, (*path, k))


def _set(doc: Any, path: tuple[Any, ...], value: Any) -> None:
    for key in path[:-1]:
        doc = doc[key]
    doc[path[-1]] = value


def _get(doc: Any, path: tuple[Any, ...]) -> Any:
    for key in path:
        doc = doc[key]
    return doc


def _dumps(doc: Any) -> bytes:
    return json.dumps(doc, separators=(",", ":")).encode()  # NaN and Infinity as JS literals


def json_mutation(parsed: _Parsed, rng: np.random.Generator) -> Mutation:
    """One random message-level mutation, written back with valid CRCs and the original
    metadata (as a careless editing tool would)."""
    msgs = [_Record(**vars(m)) for m in parsed.messages]
    kinds = [
        "value",
        "value",
        "value",
        "nudge",
        "delete_key",
        "add_key",
        "whole",
        "duplicate",
        "drop",
        "key_shift",
        "reverse_times",
        "permute_times",
        "equal_times",
    ]
    kind = str(rng.choice(kinds))
    harmless = kind in ("reverse_times", "permute_times", "equal_times")
    topics = sorted({m.topic for m in msgs})
    if harmless:
        topic = str(rng.choice(topics))
        idx = [k for k, m in enumerate(msgs) if m.topic == topic]
        times = np.array([msgs[k].log_time for k in idx])
        if kind == "reverse_times":
            times = times[::-1]
        elif kind == "permute_times":
            times = rng.permutation(times)
        else:
            times = np.full_like(times, times[0])
        for k, t in zip(idx, times, strict=True):
            msgs[k].log_time = msgs[k].publish_time = int(t)
        label = f"{kind}:{topic}"
    else:
        k = int(rng.integers(len(msgs)))
        m = msgs[k]
        doc = json.loads(m.data)
        label = f"{kind}:{m.topic}#{k}"
        if kind in ("value", "nudge", "delete_key", "key_shift") and isinstance(doc, dict):
            paths = list(_leaves(doc))
            if kind == "key_shift":
                paths = [p for p in paths if p[-1] in ("sweep", "step", "repeat")] or paths
            path = paths[int(rng.integers(len(paths)))]
            label += ":" + "/".join(map(str, path))
            old = _get(doc, path)
            if kind == "value":
                _set(doc, path, BAD_VALUES[int(rng.integers(len(BAD_VALUES)))])
            elif kind == "nudge" or kind == "key_shift":
                if isinstance(old, bool) or not isinstance(old, int | float):
                    _set(doc, path, None)
                elif isinstance(old, int):
                    _set(doc, path, old + int(rng.choice([-1, 1])))
                else:
                    _set(doc, path, old + float(rng.choice([-0.01, 0.01, 0.5])))
            else:
                parent = _get(doc, path[:-1])
                if isinstance(parent, dict):
                    del parent[path[-1]]
                else:
                    parent.pop(path[-1])
            m.data = _dumps(doc)
        elif kind == "add_key" and isinstance(doc, dict):
            doc["unexpected"] = 1.0
            m.data = _dumps(doc)
        elif kind == "duplicate":
            msgs.insert(k + 1, _Record(**vars(m)))
        elif kind == "drop":
            del msgs[k]
        else:
            m.data = _dumps([None, [], "x", {}, 3][int(rng.integers(5))])
            label = f"whole:{m.topic}#{k}"
    out = _Parsed(
        parsed.profile,
        parsed.library,
        parsed.schemas,
        parsed.channels,
        parsed.metadata,
        msgs,
    )
    return Mutation(label, unparse(out), harmless)


# --------------------------------------------------------------------------- running


class Timeout(KeyboardInterrupt):
    """No answer in time: a KeyboardInterrupt, which the command line re-raises (a plain
    exception inside a command would be reported as an internal error, exit 70)."""


@contextlib.contextmanager
def alarm(seconds: float) -> Iterator[None]:
    def handler(signum: int, frame: Any) -> None:
        raise Timeout

    old = signal.signal(signal.SIGALRM, handler)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)


def tool_positions(signature_path: Path) -> np.ndarray:
    """Signature tool positions (cm) at fixed random configurations within the limits."""
    from pipeline.kinematics.chain import forward_kinematics
    from pipeline.signature.file import load_signature
    from pipeline.units import joints_to_internal

    sig = load_signature(signature_path)
    lim = sig.robot.limits
    q = np.random.default_rng(0).uniform(lim[:, 0], lim[:, 1], (CONFIGURATIONS, lim.shape[0]))
    return forward_kinematics(sig.chain, joints_to_internal(q, sig.prismatic))[:, :3, 3]


@dataclass(frozen=True)
class Outcome:
    label: str
    result: str  # refused, same, or one of FAILURES
    detail: str


def identify_copy(data: bytes, workdir: Path, name: str) -> Path:
    """Identify ``data`` as ``workdir/name/recording.mcap``; return the signature path."""
    from pipeline.identify import identify

    sdir = workdir / name
    sdir.mkdir(parents=True)
    (sdir / "recording.mcap").write_bytes(data)
    return identify(sdir, report=False).signature


def run_one(mutation: Mutation, reference: np.ndarray, workdir: Path, name: str) -> Outcome:
    """Identify one mutation and classify the outcome (module docstring)."""
    import warnings

    from pipeline.errors import ArmsigError

    try:
        with alarm(TIMEOUT_S), warnings.catch_warnings():
            warnings.simplefilter("ignore")
            sig = identify_copy(mutation.data, workdir, name)
            positions = tool_positions(sig)
    except Timeout:
        return Outcome(mutation.label, "hang", f"no answer within {TIMEOUT_S:g} s")
    except ArmsigError as exc:
        text = str(exc)
        return Outcome(mutation.label, "multiline" if "\n" in text else "refused", text[:300])
    except Exception as exc:  # noqa: BLE001 - counting every unexpected exception is the point
        return Outcome(mutation.label, "traceback", f"{type(exc).__name__}: {exc}"[:300])
    finally:
        shutil.rmtree(workdir / name, ignore_errors=True)
    diff = float(np.max(np.abs(positions - reference)))
    if mutation.harmless and diff != 0.0:
        return Outcome(mutation.label, "reordered", f"signature moved {diff:.3e} cm")
    if diff > SAME_CM:
        return Outcome(mutation.label, "changed", f"signature moved {diff:.3e} cm, exit 0")
    return Outcome(mutation.label, "same", f"{diff:.1e} cm")


def fuzz(
    recording: Path,
    n_byte: int,
    n_json: int,
    seed: int = 0,
    budget_s: float | None = None,
    progress: Callable[[int, Outcome], None] | None = None,
) -> list[Outcome]:
    """Run ``n_byte`` byte-level and ``n_json`` JSON-level mutations of ``recording``,
    interleaved, stopping early once ``budget_s`` seconds of this process's CPU time have
    passed: CPU, not wall-clock, so that a loaded machine or parallel test workers do not
    shrink the sample (the mutations are identified in this process)."""
    original = recording.read_bytes()
    parsed = parse(original)
    rng = np.random.default_rng(seed)
    out: list[Outcome] = []
    t0 = time.process_time()
    with tempfile.TemporaryDirectory(prefix="armsig-fuzz-") as tmp:
        work = Path(tmp)
        reference = tool_positions(identify_copy(original, work, "original"))
        plan = ["byte"] * n_byte + ["json"] * n_json
        order = rng.permutation(len(plan))
        for k, which in enumerate(plan[i] for i in order):
            if budget_s is not None and time.process_time() - t0 > budget_s:
                break
            mutation = (
                byte_mutation(original, rng) if which == "byte" else json_mutation(parsed, rng)
            )
            outcome = run_one(mutation, reference, work, f"m{k}")
            out.append(outcome)
            if progress:
                progress(k, outcome)
    return out


def summary(outcomes: list[Outcome]) -> str:
    """Counts per result, and every failure with its detail."""
    counts = Counter(o.result for o in outcomes)
    lines = [f"{len(outcomes)} mutations: " + ", ".join(f"{k} {v}" for k, v in counts.items())]
    lines += [f"  {o.result:10s} {o.label}: {o.detail}" for o in outcomes if o.result in FAILURES]
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("recording", nargs="?", default="sessions/robot3/recording.mcap")
    ap.add_argument("--byte", type=int, default=500, help="byte-level mutations")
    ap.add_argument("--json", type=int, default=200, help="JSON-level mutations")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    t0 = time.perf_counter()

    def show(k: int, o: Outcome) -> None:
        if o.result in FAILURES:
            print(f"[{k}] {o.result}: {o.label}: {o.detail}", flush=True)

    outcomes = fuzz(Path(args.recording), args.byte, args.json, args.seed, progress=show)
    print(summary(outcomes))
    print(f"{time.perf_counter() - t0:.1f} s")
    sys.exit(1 if any(o.result in FAILURES for o in outcomes) else 0)


if __name__ == "__main__":
    main()

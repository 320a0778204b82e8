"""The session lock: one pipeline run per session folder at a time.

A kernel lock (``flock``) on ``SESSION/.pipeline.lock``: the kernel drops it when its
holder exits, however it exits, so the file's content (empty, a reused PID) means
nothing and the file stays. A second run, in another process or thread, is refused
at once with :class:`SessionLockedError`.
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import os
import threading
from collections.abc import Iterator
from pathlib import Path

from pipeline.errors import SessionLockedError, StageError

LOCK_NAME = ".pipeline.lock"

#: Session locks this thread holds: lock path -> depth (a run inside ``identify`` re-enters).
_held = threading.local()


@contextlib.contextmanager
def session_lock(session_dir: Path) -> Iterator[None]:
    """Exclusive kernel lock (``flock``) on a session folder, re-entrant within a thread.

    A second run (another process or thread) gets :class:`SessionLockedError` at once.
    The kernel drops the lock when its holder exits, however it exits, so the lock
    file's content (empty, a reused PID) means nothing and the file stays.
    """
    sdir = Path(session_dir)
    if not sdir.is_dir():
        raise StageError(f"{sdir}: no such session folder", fix="check the path")
    path = sdir.resolve() / LOCK_NAME
    depth: dict[Path, int] = _held.__dict__.setdefault("depth", {})
    if path in depth:
        depth[path] += 1
        try:
            yield
        finally:
            depth[path] -= 1
        return
    try:
        fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW, 0o644)
    except OSError as exc:
        raise SessionLockedError(
            f"{sdir}: cannot open the session lock {path}",
            expected="a writable session folder where the lock is a file",
            got=exc.strerror or str(exc),
            fix=f"remove the folder {path}" if path.is_dir() else f"make {sdir} writable",
        ) from None
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError as exc:
        os.close(fd)
        if exc.errno in (errno.EWOULDBLOCK, errno.EACCES):
            raise SessionLockedError(
                f"{sdir}: another pipeline run is working on this session",
                fix="wait for it to finish (its lock goes when its process ends)",
            ) from None
        raise SessionLockedError(
            f"{sdir}: cannot lock {path}", got=exc.strerror or str(exc)
        ) from None
    depth[path] = 1
    try:
        yield
    finally:
        del depth[path]
        os.close(fd)  # releases the flock

"""Write files atomically: a temp file in the same folder, then rename.

A reader never sees a half-written file, and a failure leaves the previous
version untouched.
"""

from __future__ import annotations

import contextlib
import json
import os
import tempfile
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import IO

#: Temp files are ``.<name>.<random>.tmp`` beside their target.
TEMP_SUFFIX = ".tmp"
#: A session's measured inputs: no command writes over them, not even with ``--force``.
SESSION_INPUTS = ("recording.mcap", "evaluation.mcap")


#: What to try when a file cannot be written (an OSError of :func:`atomic_write`).
WRITE_FIX = "check the free space and that the file and its folder are writable (chattr, chmod)"


@contextlib.contextmanager
def atomic_write(path: str | Path, mode: str = "wb") -> Iterator[IO[bytes] | IO[str]]:
    """Open a temp file beside ``path``; on success rename it over ``path``. An OSError
    (no space, permission, an immutable file, a name too long) is an
    :class:`~pipeline.errors.ArmsigError` naming ``path`` and the cause."""
    from pipeline.errors import os_errors_refused

    target = Path(path)
    with os_errors_refused(target, WRITE_FIX, always_path=True):
        target.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.", suffix=TEMP_SUFFIX, dir=target.parent)
        umask = os.umask(0)
        os.umask(umask)
        try:
            os.chmod(tmp, 0o666 & ~umask)  # mkstemp makes 0600; give the file normal permissions
            with os.fdopen(fd, mode) as fh:
                yield fh
                fh.flush()
                os.fsync(fh.fileno())
            os.replace(tmp, target)
        except BaseException:
            with contextlib.suppress(FileNotFoundError):
                os.unlink(tmp)
            raise


def remove_debris(folder: Path) -> list[Path]:
    """Delete the temp files that killed writers left in ``folder`` (not its subfolders).

    Only safe while no writer of ``folder`` is running: call it under the session lock.
    """
    gone = []
    for tmp in folder.glob(f".*{TEMP_SUFFIX}") if folder.is_dir() else ():
        if tmp.is_file() and not tmp.is_symlink():
            with contextlib.suppress(FileNotFoundError):
                tmp.unlink()
                gone.append(tmp)
    return gone


def write_text_atomic(path: str | Path, text: str) -> None:
    """Atomically write ``text`` (UTF-8) to ``path``."""
    with atomic_write(path, "wb") as fh:
        fh.write(text.encode("utf-8"))  # type: ignore[arg-type]


def write_unless_same_inputs(
    path: Path, stamp: Path, inputs: dict[str, str | None], write: Callable[[], Path]
) -> Path:
    """Call ``write`` (which writes ``path``) unless ``stamp`` records the same ``inputs``
    (e.g. stage content hashes) as the run that wrote the existing ``path``; then record
    them. A warm run leaves the file, and its figures, untouched."""
    current = json.dumps(inputs, sort_keys=True)
    if path.is_file() and stamp.is_file() and stamp.read_text() == current:
        return path
    out = write()
    write_text_atomic(stamp, current)
    return out


def check_writable(path: str | Path, what: str, *, folder: bool = False) -> Path:
    """Refuse, before any work is done, an output ``path`` that cannot be written.

    A file (``folder=False``) needs an existing, writable parent folder and must not
    be a folder itself; a folder (``folder=True``) must be a folder or not exist yet,
    and its nearest existing ancestor must be a writable folder (the missing ones are
    made when the output is written). ``what`` names the output in the message, e.g.
    ``"--out"``. Returns ``path`` as a :class:`Path`.
    """
    from pipeline.errors import os_errors_refused

    p = Path(path)
    with os_errors_refused(p, "give a shorter path, or one you can read"):  # a name too long
        return _check_writable(p, what, folder)


def _check_writable(p: Path, what: str, folder: bool) -> Path:
    from pipeline.errors import ArmsigError

    if folder:
        if p.exists() and not p.is_dir():
            raise ArmsigError(f"{what} {p} is a file", expected="a folder (or a new path)")
        parent = next(a for a in (p, *p.absolute().parents) if a.exists())
    else:
        if p.is_dir():
            raise ArmsigError(f"{what} {p} is a folder", expected="a file path")
        if p.resolve().name in SESSION_INPUTS:
            raise ArmsigError(
                f"{what} {p} is a session's measurements, which no command writes over",
                fix="give another file name",
            )
        parent = p.absolute().parent
        if not parent.exists():
            raise ArmsigError(
                f"{what} {p}: folder {parent} does not exist", fix="create it, or give another path"
            )
    if not parent.is_dir():
        raise ArmsigError(f"{what} {p}: {parent} is not a folder", fix="give another path")
    try:
        with tempfile.TemporaryFile(dir=parent):
            pass
    except OSError as exc:
        raise ArmsigError(
            f"{what} {p}: cannot write in {parent}", got=exc.strerror or str(exc),
            fix="give a path in a writable folder",
        ) from exc  # fmt: skip
    return p


def check_new_file(
    path: str | Path, what: str, force: bool, inputs: Sequence[str | Path] = ()
) -> Path:
    """:func:`check_writable`, and refuse a file that exists unless ``force`` (a user's
    file is never replaced without asking). ``force`` replaces a user's output, never one
    of the command's ``inputs`` nor a session's own files (:func:`session_own_file`)."""
    from pipeline.errors import ArmsigError

    p = check_writable(path, what)
    if not p.exists():
        return p
    same = next((str(i) for i in inputs if Path(i).exists() and Path(i).samefile(p)), None)
    if same is not None:
        raise ArmsigError(
            f"{what} {p} is an input of this command ({same})",
            expected="an output file other than the inputs, which --force never replaces",
            fix="give another path",
        )
    own = session_own_file(p)
    if own is not None:
        raise ArmsigError(
            f"{what} {p} is {own}, which only `pipeline identify` writes",
            expected="an output file outside the session's stages, report and signature",
            fix=f"give another path, e.g. {p.parent / ('my-' + p.name)}",
        )
    if not force:
        raise ArmsigError(f"{what} {p} already exists", fix="another path, or --force")
    return p


#: A session's own files and folders (beside its ``recording.mcap``), which identify writes.
SESSION_OWN = ("signature.json", "rig-truth.json", "stages", "report")


def session_own_file(path: str | Path) -> str | None:
    """What ``path`` is when it is a session's own file: its ``signature.json``, its
    simulator's truth, or a file under its ``stages/`` or ``report/`` folder (a folder
    holding a ``recording.mcap``); else None."""
    p = Path(path).resolve()
    for top in (p, *p.parents[:-1]):
        if top.name in SESSION_OWN and (top.parent / SESSION_INPUTS[0]).is_file():
            return f"session {top.parent.name}'s {top.relative_to(top.parent)}"
    return None

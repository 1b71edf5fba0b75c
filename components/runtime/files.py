"""Writing a user's file: atomically, and never through a symlink someone planted.

The old pattern - write ``NAME.tmp`` (or ``.NAME.tmp``), copy the old file to ``NAME.bak``,
rename the temporary over ``NAME`` - opens fixed, guessable names: a symlink planted at
``NAME.tmp`` or ``NAME.bak`` made the writer overwrite the file it points at (and renamed the
symlink itself into place: ``rig.toml`` became a link; issue 29).  Here:

- the temporary file is created beside the target (same file system: the rename is atomic)
  under a random name, with ``O_CREAT | O_EXCL | O_NOFOLLOW``: it is always a new regular
  file, never an existing file or a link's target; it is written, flushed to the disk
  (``fsync``) and renamed over the target with ``os.replace``, which replaces a link at the
  target's name by the file, never writing into what the link points at;
- a backup (``NAME.bak``) is written the same way, so a link planted there is replaced, its
  target untouched;
- on any error the temporary file is removed and the target is as it was.

A crash leaves the old file or the new one, never half of one.
"""

from __future__ import annotations

import contextlib
import os
import secrets
from collections.abc import Iterator
from pathlib import Path
from typing import IO

__all__ = ["atomic_open", "write_atomic", "backup_name"]

_FLAGS = (os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_CLOEXEC", 0)
          | getattr(os, "O_BINARY", 0))


def backup_name(path: str | Path) -> Path:
    """Where :func:`write_atomic` keeps the previous content: ``NAME.bak`` beside it."""
    p = Path(path)
    return p.with_name(p.name + ".bak")


def _create_temp(target: Path, mode: int) -> tuple[Path, int]:
    """A new regular file beside ``target`` under a random name (never an existing name)."""
    for _ in range(100):
        tmp = target.with_name(f".{target.name}.{secrets.token_hex(8)}.tmp")
        try:
            return tmp, os.open(tmp, _FLAGS, mode)
        except FileExistsError:
            continue
    raise FileExistsError(f"{target.parent}: could not create a temporary file for {target.name}")


def _sync_dir(d: Path) -> None:
    """The rename itself reaches the disk (best effort: not every file system allows it)."""
    try:
        fd = os.open(d, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0))
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


@contextlib.contextmanager
def atomic_open(path: str | Path, mode: str = "w", *, backup: bool = False, perm: int = 0o666,
                fsync: bool = True, **open_kw) -> Iterator[IO]:
    """``with atomic_open(path) as f: f.write(...)``: the file written into appears at
    ``path`` when the block ends without an exception (see the module docstring).  ``mode``
    is ``"w"`` (text; ``open_kw`` as for :func:`open`, e.g. ``newline=""``) or ``"wb"``.
    ``backup``: the current content of ``path``, if there is one, is first kept as
    ``NAME.bak``.  ``perm`` is masked by the umask, as :func:`open` does."""
    if mode not in ("w", "wb"):
        raise ValueError(f"atomic_open: mode {mode!r} is not 'w' or 'wb'")
    target = Path(path)
    if mode == "w":
        open_kw.setdefault("encoding", "utf-8")
    tmp, fd = _create_temp(target, perm)
    try:
        with os.fdopen(fd, mode, **open_kw) as f:
            yield f
            f.flush()
            if fsync:
                os.fsync(f.fileno())
        if backup and os.path.lexists(target) and target.is_file():
            with open(target, "rb") as old:  # the user's own file (a link they made is theirs)
                data = old.read()
            write_atomic(backup_name(target), data, fsync=fsync)
        os.replace(tmp, target)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise
    if fsync:
        _sync_dir(target.parent)


def write_atomic(path: str | Path, data: str | bytes, *, backup: bool = False, fsync: bool = True,
                 encoding: str = "utf-8") -> Path:
    """Write ``data`` (text or bytes) to ``path`` atomically, never through a planted link;
    ``backup``: keep the previous content as ``NAME.bak`` (written the same way)."""
    raw = data.encode(encoding) if isinstance(data, str) else bytes(data)
    with atomic_open(path, "wb", backup=backup, fsync=fsync) as f:
        f.write(raw)
    return Path(path)

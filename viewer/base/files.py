"""Files written so that a failure never leaves a half-written or destroyed one.

``write_atomic`` replaces a file in one rename; ``AtomicSet`` replaces several
together; ``write_new`` takes the first free name of a list without ever
overwriting.  Every output of the program (images, scenes, results) goes
through here.
"""

from __future__ import annotations

import errno
import itertools
import os
import tempfile
from pathlib import Path


def _new_file_mode() -> int:
    """The mode a plain open() gives a new file: 0666 less the umask."""
    umask = os.umask(0)
    os.umask(umask)
    return 0o666 & ~umask


def _write_temp(folder: Path, name: str, data: bytes, mode: int) -> str:
    """A temporary file in `folder` (named after `name`) holding `data`,
    flushed to disk, with `mode`; its path.  Removed again if that fails."""
    fd, tmp = tempfile.mkstemp(prefix=f".{name}.", suffix=".tmp", dir=folder)
    try:
        f = os.fdopen(fd, "wb")           # (closes fd whatever happens next)
        try:
            os.chmod(tmp, mode)           # mkstemp makes it 0600
        except OSError:
            pass  # a file system without modes (FAT, some network mounts): the file is still written
        with f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
    except BaseException:
        _unlink_quietly(tmp)
        raise
    return tmp


def _unlink_quietly(path: str) -> None:
    try:
        os.unlink(path)
    except OSError:
        pass


def write_atomic(path: Path, data: bytes) -> None:
    """Write to a temporary file beside ``path`` and rename it into place, so a
    failed write never leaves a half-written or destroyed file.  A symbolic
    link is followed: the file it points to is replaced and the link kept,
    as a plain open() for writing would."""
    tmp, path = _stage(path, data)
    try:
        os.replace(tmp, path)
    except BaseException:
        _unlink_quietly(tmp)
        raise


def _stage(path: Path, data: bytes) -> tuple[str, Path]:
    """`data` in full in a temporary file beside `path` (its link's target,
    for a symbolic link), checked as a plain open() for writing would check
    `path`; (the temporary file, the path to rename it to)."""
    path = Path(path)
    if path.is_symlink():
        path = Path(os.path.realpath(path))
    # a rename replaces a file whatever its own mode: one the user made
    # read-only is refused, as a plain open() for writing refuses it
    if path.exists() and not path.is_dir() and not os.access(path, os.W_OK):
        raise PermissionError(errno.EACCES, os.strerror(errno.EACCES), str(path))
    try:
        mode = path.stat().st_mode & 0o7777      # the existing file's, as open() keeps it
    except OSError:
        mode = _new_file_mode()
    return _write_temp(path.parent, path.name, data, mode), path


class AtomicSet:
    """Files written as one set (a benchmark's CSV, tables and plots): each
    is written in full beside its name first, and only when every one is
    are they renamed into place, and the files to remove removed.  An error
    before that (a full disk, a read-only file among them, Ctrl-C) leaves
    every file as it was, never some of one run and some of another.  (The
    renames themselves could still fail part way: they do not allocate,
    so only a folder changed under the run can make them fail.)"""

    def __init__(self) -> None:
        self._staged: list[tuple[str, Path]] = []
        self._removals: list[Path] = []

    def write(self, path: Path, data: bytes) -> None:
        self._staged.append(_stage(path, data))

    def remove(self, path: Path) -> None:
        self._removals.append(Path(path))

    def commit(self) -> None:
        staged, self._staged = self._staged, []
        try:
            while staged:
                tmp, path = staged[0]
                os.replace(tmp, path)
                staged.pop(0)
        finally:
            for tmp, _ in staged:
                _unlink_quietly(tmp)
        removals, self._removals = self._removals, []
        for path in removals:
            path.unlink(missing_ok=True)

    def discard(self) -> None:
        for tmp, _ in self._staged:
            _unlink_quietly(tmp)
        self._staged, self._removals = [], []


def write_new(paths, data: bytes) -> Path:
    """Write `data` under the first of `paths` (an iterable of names in one
    folder, tried in order) that no file has, and return it.  Never
    replaces a file, also one another program creates between the check
    and the write (two viewers saving a screenshot in the same second): the
    complete file is linked to the name, which fails if the name is taken.
    Where the file system has no hard links, the name is created exclusively
    (O_EXCL) and written: still never a replaced file; a failed write
    removes it, but a crash during the write can leave a short one."""
    paths = iter(paths)
    first = Path(next(paths))
    tmp = _write_temp(first.parent, first.name, data, _new_file_mode())
    try:
        linked = True
        for path in itertools.chain([first], map(Path, paths)):
            if linked:
                try:
                    os.link(tmp, path)
                    return path
                except FileExistsError:
                    continue
                except OSError as e:
                    if e.errno not in (errno.EPERM, errno.ENOTSUP, errno.EOPNOTSUPP, errno.EMLINK, errno.ENOSYS):
                        raise
                    linked = False               # no hard links here: exclusive creation instead
            try:
                f = open(path, "xb")
            except FileExistsError:
                continue
            try:
                with f:
                    f.write(data)
                    f.flush()
                    os.fsync(f.fileno())
            except BaseException:
                _unlink_quietly(str(path))           # ours, and short: no half-written screenshot
                raise
            return path
        raise FileExistsError(errno.EEXIST, "every name is taken", str(first))
    finally:
        _unlink_quietly(tmp)



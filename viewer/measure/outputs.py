"""A run's result files: written atomically, as one set, with the file named
when it cannot be written; the results folder checked before a run.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from pathlib import Path

from ..base.files import AtomicSet, write_atomic


class OutputError(Exception):
    """An output file could not be written (the message names it)."""


#: the set of files being written together (results_written_together), if any
_writing: "AtomicSet | None" = None


def write_output(path: Path, data: bytes) -> None:
    """write_atomic (or, inside results_written_together, a part of its
    set), with an OSError (a full disk, a read-only folder) turned into an
    OutputError that names the file: the OSError of a failed write names at
    most the temporary file, and often nothing."""
    try:
        if _writing is not None:
            _writing.write(path, data)
        else:
            write_atomic(path, data)
    except OSError as e:
        raise OutputError(f"{path}: cannot write: {e.strerror or e}") from e


@contextlib.contextmanager
def results_written_together():
    """A run's result files as one set: every write_output and remove_stale
    inside is done at the end, all of them, or none if anything inside
    fails (a second run into the same folder that cannot write one of its
    files leaves the first run's files, all of them, as they were)."""
    global _writing
    outer, _writing = _writing, AtomicSet()
    files = _writing
    try:
        yield
    except BaseException:
        files.discard()
        raise
    finally:
        _writing = outer
    try:
        files.commit()
    except OSError as e:
        raise OutputError(f"{e.filename or 'a result file'}: cannot write: {e.strerror or e}") from e


def results_folder_problem(out: Path) -> str | None:
    """Why results cannot be written into the folder `out` (made if
    missing; its parent must exist), or None: checked before a run, not
    found after it."""
    if out.exists() and not out.is_dir():
        return f"{out}: cannot write results there: it is a file, not a folder"
    if not out.parent.is_dir():      # as render's output: a mistyped path is not made
        what = "is a file, not a folder" if out.parent.exists() else "does not exist"
        return f"{out}: cannot write results there: folder {out.parent} {what}"
    try:
        out.mkdir(exist_ok=True)
        fd, probe = tempfile.mkstemp(prefix=".glassray-write-test-", dir=out)   # a name no file has
        os.close(fd)
        os.unlink(probe)
    except OSError as e:
        return f"{out}: cannot write results there: {e.strerror or e}"
    return None


def remove_stale(paths: list[Path]) -> list[Path]:
    """Remove the files of `paths` that exist (an earlier run's plots, which
    would pass for this run's); returns those removed."""
    stale = [p for p in paths if p.is_file()]
    for p in stale:
        if _writing is not None:        # with the set's other files, at its end
            _writing.remove(p)
            continue
        try:
            p.unlink()
        except OSError as e:
            raise OutputError(f"{p}: an earlier run's plot, cannot remove it: {e.strerror or e}") from e
    return stale


def remove_if_empty(folder: Path) -> None:
    """Remove `folder` if it is empty (results_folder_problem made it, and
    the run failed before writing anything into it)."""
    try:
        folder.rmdir()                # fails on a folder with anything in it
    except OSError:
        pass

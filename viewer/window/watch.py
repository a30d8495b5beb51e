"""Watching files for the viewer's live reload, without threads or GLFW.

FileWatcher remembers each path's (inode, size, mtime); poll() says which
changed since the last reload, once the change has held still for the
debounce time (an editor that writes a file in pieces, or that writes a
temporary file and renames it over the original as vim and VS Code do,
reloads once, with the whole file).  A path that is missing for a moment
(between an unlink and a rename) counts as changed only when it comes back
or stays away.  The viewer calls poll() from its loop, which wakes at least
every IDLE_WAKE_S even when idle, so a save is seen within about that long
and an idle window costs one stat() per file per wake.
"""

from __future__ import annotations

import os
import time
from pathlib import Path

#: A change is taken once the files' stats have held still this long (s).
DEBOUNCE_S = 0.08
#: poll() looks at the disk at most this often (s); calls in between are free.
POLL_EVERY_S = 0.05


def _stamp(path: Path):
    """What tells a new version of a file: (inode, size, mtime in ns), or
    None while it is missing or unreadable."""
    try:
        st = os.stat(path)
    except OSError:
        return None
    return (st.st_ino, st.st_size, st.st_mtime_ns)


def shader_files(root: Path) -> list[Path]:
    """The GLSL sources under root (entry files and lib/)."""
    return sorted(p for p in Path(root).rglob("*") if p.suffix in (".frag", ".vert", ".glsl"))


class FileWatcher:
    def __init__(self, paths, debounce_s: float = DEBOUNCE_S, poll_every_s: float = POLL_EVERY_S,
                 clock=time.monotonic):
        self.clock = clock
        self.debounce_s = debounce_s
        self.poll_every_s = poll_every_s
        self._paths: list[Path] = []
        self._known: dict[Path, object] = {}
        self._seen: dict[Path, object] = {}     # the stamps of the change being debounced
        self._since = None                      # when those stamps were first seen
        self._last_poll = -float("inf")
        self.watch(paths)

    @property
    def paths(self) -> list[Path]:
        return list(self._paths)

    def watch(self, paths) -> None:
        """Watch these paths from now on (their present versions are the
        known ones: a reload has just read them)."""
        self._paths = [Path(p) for p in paths]
        self.rebase()

    def rebase(self) -> None:
        """The files as they are now are the loaded ones (after a reload,
        good or not: a failed one waits for the next save)."""
        self._known = {p: _stamp(p) for p in self._paths}
        self._seen, self._since = {}, None

    def poll(self) -> list[Path]:
        """The watched paths that changed and have held still for the
        debounce time ([] otherwise).  The caller reloads, then rebase()s."""
        now = self.clock()
        if now - self._last_poll < self.poll_every_s:
            return []
        self._last_poll = now
        stamps = {p: _stamp(p) for p in self._paths}
        changed = {p: s for p, s in stamps.items() if s != self._known.get(p)}
        if not changed:
            self._seen, self._since = {}, None
            return []
        if changed != self._seen:              # new, or still moving: start the debounce over
            self._seen, self._since = changed, now
            return []
        if now - self._since < self.debounce_s:
            return []
        return sorted(changed)

    def pending(self) -> bool:
        """A change is being debounced: the loop should come back soon."""
        return self._since is not None

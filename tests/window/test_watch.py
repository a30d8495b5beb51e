"""The live reload's file watcher (viewer/window/watch.py), without a window:
a save in place, a write-and-rename as editors do it, a file missing for a
moment, debouncing of a file written in pieces, and the rate of its stats.
The clock is the test's, so every case is exact."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from viewer.window.watch import FileWatcher, shader_files


class Clock:
    def __init__(self):
        self.t = 100.0

    def __call__(self) -> float:
        return self.t

    def tick(self, dt: float) -> None:
        self.t += dt


@pytest.fixture
def watched(tmp_path):
    f = tmp_path / "scene.toml"
    f.write_text('name = "a"\n')
    clock = Clock()
    return f, clock, FileWatcher([f], debounce_s=0.1, poll_every_s=0.02, clock=clock)


def settle(w: FileWatcher, clock: Clock, seconds: float, step: float = 0.03) -> list[Path]:
    """Poll as the viewer's loop does for `seconds`; what the last polls said."""
    seen: list[Path] = []
    end = clock.t + seconds
    while clock.t < end:
        clock.tick(step)
        seen = w.poll() or seen
    return seen


def test_nothing_changed_nothing_reported(watched):
    f, clock, w = watched
    assert settle(w, clock, 1.0) == [] and not w.pending()


def test_a_save_in_place_is_reported_once_it_holds_still(watched):
    f, clock, w = watched
    clock.tick(1)
    f.write_text('name = "b"\n')
    os.utime(f, ns=(1, 2_000_000_000))        # a new mtime whatever the file system's resolution
    clock.tick(0.03)
    assert w.poll() == [] and w.pending()       # seen, not yet still for the debounce time
    assert settle(w, clock, 0.2) == [f]
    w.rebase()                                  # the viewer reloaded
    assert settle(w, clock, 0.5) == [] and not w.pending()


def test_a_write_and_rename_is_a_change_of_the_same_path(watched, tmp_path):
    f, clock, w = watched
    tmp = tmp_path / ".scene.toml.swp"
    tmp.write_text('name = "renamed"\n')
    os.replace(tmp, f)                          # a new inode under the old name
    assert settle(w, clock, 0.3) == [f]


def test_a_file_missing_for_a_moment_is_one_change(watched, tmp_path):
    f, clock, w = watched
    f.unlink()
    clock.tick(0.03)
    assert w.poll() == []                       # gone: not reported while it may come back
    f.write_text('name = "back"\n')
    os.utime(f, ns=(1, 3_000_000_000))
    assert settle(w, clock, 0.3) == [f]
    # and one that stays away is reported too (the reload then says it is missing)
    w.rebase()
    f.unlink()
    assert settle(w, clock, 0.3) == [f]


def test_a_file_written_in_pieces_waits_for_the_last_piece(watched):
    f, clock, w = watched
    for k in range(5):                          # a piece every 50 ms: never still for 100 ms
        with open(f, "a") as fh:
            fh.write(f"# piece {k}\n")
        clock.tick(0.05)
        assert w.poll() == [], k
    assert settle(w, clock, 0.3) == [f]


def test_polls_between_intervals_do_not_touch_the_disk(watched, monkeypatch):
    f, clock, w = watched
    calls = []
    import viewer.window.watch as watch

    real = watch.os.stat
    monkeypatch.setattr(watch.os, "stat", lambda p: calls.append(p) or real(p))
    for _ in range(10):
        clock.tick(0.001)
        w.poll()
    assert len(calls) <= 1
    clock.tick(0.05)
    w.poll()
    assert len(calls) <= 2


def test_shader_files_are_the_glsl_sources(tmp_path):
    (tmp_path / "lib").mkdir()
    for name in ("render.frag", "fullscreen.vert", "lib/walk.glsl", "README.md", "lib/notes.txt"):
        (tmp_path / name).write_text("x")
    assert [p.relative_to(tmp_path).as_posix() for p in shader_files(tmp_path)] == [
        "fullscreen.vert", "lib/walk.glsl", "render.frag"]

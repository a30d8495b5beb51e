"""Screenshots never replace a file, also one that another program saves
under the same name between the choice of the name and the write (two
viewers in one folder, F12 in the same second)."""

from __future__ import annotations

import errno
import os
import tempfile

import numpy as np
import pytest

from viewer.base import files as files_mod
from viewer.window.screenshot import save_linear, save_rgb8, screenshot_path

WHEN = 1_700_000_000.0
OTHERS = b"another program's screenshot"


@pytest.fixture
def rival(monkeypatch, tmp_path):
    """When the saver makes its temporary file (after it chose a name, before
    the name holds the file), another program saves the first free name."""
    real = tempfile.mkstemp
    taken = []

    def mkstemp(*a, **kw):
        if not taken:
            p = screenshot_path(tmp_path, WHEN)
            p.write_bytes(OTHERS)
            taken.append(p)
        return real(*a, **kw)
    monkeypatch.setattr(files_mod.tempfile, "mkstemp", mkstemp)
    return taken


@pytest.mark.parametrize("save", ["linear", "rgb8"])
def test_a_name_taken_meanwhile_is_not_replaced(rival, tmp_path, save):
    if save == "linear":
        p = save_linear(np.full((2, 3, 3), 0.5, np.float32), tmp_path, WHEN)
    else:
        p = save_rgb8(np.full((2, 3, 3), 188, np.uint8), tmp_path, WHEN)
    (theirs,) = rival
    assert theirs.read_bytes() == OTHERS              # theirs kept
    assert p.name == theirs.name[:-4] + "-2.png"      # ours under the next name
    from PIL import Image

    with Image.open(p) as im:
        assert im.size == (3, 2) and im.getpixel((0, 0)) == (188, 188, 188)
    assert sorted(f.name for f in tmp_path.iterdir()) == sorted([theirs.name, p.name])  # no temporary left


def test_without_hard_links_names_are_still_never_replaced(monkeypatch, rival, tmp_path):
    def no_link(src, dst, *a, **kw):
        raise OSError(errno.EPERM, "Operation not permitted")
    monkeypatch.setattr(files_mod.os, "link", no_link)
    img = np.full((2, 3, 3), 0.5, np.float32)
    p = save_linear(img, tmp_path, WHEN)
    q = save_linear(img, tmp_path, WHEN)
    (theirs,) = rival
    assert theirs.read_bytes() == OTHERS
    assert [p.name, q.name] == [theirs.name[:-4] + "-2.png", theirs.name[:-4] + "-3.png"]
    assert p.read_bytes() == q.read_bytes() and p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert len(list(tmp_path.iterdir())) == 3


def test_a_new_screenshot_gets_the_mode_a_plain_open_gives(tmp_path):
    umask = os.umask(0o022)
    try:
        p = save_linear(np.zeros((1, 1, 3), np.float32), tmp_path, WHEN)
    finally:
        os.umask(umask)
    assert p.stat().st_mode & 0o777 == 0o644


def test_a_failed_write_without_hard_links_leaves_no_short_file(monkeypatch, tmp_path):
    monkeypatch.setattr(files_mod.os, "link", lambda *a, **kw: (_ for _ in ()).throw(OSError(errno.EPERM, "no")))
    real_fsync = os.fsync
    calls = []

    def fsync(fd):
        calls.append(fd)
        if len(calls) == 2:                           # the temporary file's passes, the named file's fails
            raise OSError(errno.ENOSPC, "No space left on device")
        return real_fsync(fd)
    monkeypatch.setattr(files_mod.os, "fsync", fsync)
    with pytest.raises(OSError):
        save_linear(np.zeros((1, 1, 3), np.float32), tmp_path, WHEN)
    assert list(tmp_path.iterdir()) == []

"""Every Python example a user reads runs: each ```python block of README.md
and docs/*.md (docs/notes/ are lab notebooks, not examples) is executed in a
fresh interpreter, in an empty folder, and each ``print(...)  # TEXT`` line's
TEXT is the line that call prints.  A block that fails, or prints something
else than its comment says, fails here with the document and the block."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]


def python_blocks(text: str) -> list[str]:
    return re.findall(r"^```python[ \t]*\n(.*?)^```[ \t]*$", text, flags=re.S | re.M)


def promised(block: str) -> list[str]:
    """The outputs a block's comments promise: TEXT of each `print(...)  # TEXT`."""
    return [m.group(1).strip() for m in re.finditer(r"^\s*print\(.*\)\s+#\s?(.*)$", block, flags=re.M)]


def problems(block: str, stdout: str) -> list[str]:
    """Promised lines missing from stdout, in order."""
    lines = [" ".join(line.split()) for line in stdout.splitlines()]
    out, at = [], 0
    for want in promised(block):
        want = " ".join(want.split())
        try:
            at = lines.index(want, at) + 1
        except ValueError:
            out.append(f"promised {want!r}, printed {stdout.strip()!r}")
    return out


def _cases():
    for doc in DOCS:
        for i, block in enumerate(python_blocks(doc.read_text(encoding="utf-8"))):
            yield pytest.param(block, id=f"{doc.relative_to(ROOT).as_posix()}[{i}]")


CASES = list(_cases())


def test_there_are_examples_to_run():
    names = {c.id.split("[")[0] for c in CASES}
    assert {"README.md", "docs/api.md"} <= names, names


@pytest.mark.parametrize("block", CASES)
def test_the_example_runs_and_prints_what_it_says(block, tmp_path, gl):
    r = subprocess.run([sys.executable, "-c", block], cwd=tmp_path, capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr[-3000:]
    assert not problems(block, r.stdout)


def test_the_output_check_catches_a_wrong_promise():
    block = 'print(1 + 1)   # 3\n'
    assert problems(block, "2\n") and not problems('print(1 + 1)   # 2\n', "2\n")

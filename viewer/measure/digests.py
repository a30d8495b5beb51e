"""What identifies a cached measurement's inputs: a scene's content, the
package's own code and the shader sources, each read from the installed
files.

The caches (the bench's reference images, the ``--max-error``
measurements) are keyed by the code that decides their values, declared as
parts of the package (folders, walked, and globs of files) and digested
file by file with each file's path inside the package: an edit, a module
added, removed or moved inside those parts changes the key; an edit
elsewhere (the viewer's window code) keeps it.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

from ..gpu.shaders import shader_root
from ..scene.save import scene_to_toml

#: The installed package's folder (viewer/)
PACKAGE = Path(__file__).resolve().parents[1]


def scene_digest(scene) -> str:
    """The scene's content (its TOML, and a sky image's bytes)."""
    h = hashlib.sha256(scene_to_toml(scene).encode("utf-8"))
    if scene.sky.type == "image" and scene.sky.image_path is not None:
        try:
            h.update(Path(scene.sky.image_path).read_bytes())
        except OSError:
            pass
    return h.hexdigest()[:12]


def code_files(parts: tuple[str, ...], package: Path | None = None) -> list[Path]:
    """The .py files that ``parts`` name inside ``package`` (default: the
    installed package's folder), sorted by their path inside it: a part is
    a folder (every .py under it, walked) or a glob of files
    ("measure/quality*.py")."""
    root = PACKAGE if package is None else Path(package)
    files: set[Path] = set()
    for part in parts:
        folder = root / part
        if folder.is_dir():
            files.update(f for f in folder.rglob("*.py") if "__pycache__" not in f.relative_to(root).parts)
        else:
            files.update(f for f in root.glob(part) if f.is_file())
    return sorted(files, key=lambda f: f.relative_to(root).as_posix())


def code_digest(parts: tuple[str, ...], package: Path | None = None) -> str:
    """The digest of the files of :func:`code_files`: each one's path
    inside the package and its bytes."""
    root = PACKAGE if package is None else Path(package)
    h = hashlib.sha256()
    for f in code_files(parts, root):
        data = f.read_bytes()
        h.update(f"{f.relative_to(root).as_posix()}\0{len(data)}\0".encode())
        h.update(data)
    return h.hexdigest()[:12]


def shader_digest(root: Path | None = None) -> str:
    """The digest of the shader sources (every .frag, .vert, .glsl under
    ``root``, default the folder the renderer reads: shader_root), each
    with its path inside it."""
    root = shader_root() if root is None else Path(root)
    h = hashlib.sha256()
    for p in sorted(root.rglob("*")):
        if p.is_file() and p.suffix in (".frag", ".glsl", ".vert"):
            h.update(str(p.relative_to(root)).encode())
            h.update(p.read_bytes())
    return h.hexdigest()[:12]

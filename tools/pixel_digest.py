"""Pixel digests: prove that a refactor leaves every rendered output bit-identical.

Renders a fixed set of small images (96x54) through the public CLI only --
`PYTHON -m viewer render SCENE -o OUT --size 96x54 ...`, run with cwd=TREE so
that it imports that tree's `viewer` -- and records the sha256 of each output
file's bytes in a JSON file. Record once on the tree before the change and once
after, then compare the two files: any differing case is printed.

The set: every bundled scene in every `--view` (uniform, `--samples 4`), the
colour and samples views also `--adaptive`, a few extra cases (`--max-depth 2`,
`--seed 3`, `--samples 1`) on three scenes, and a few .png files of the same
settings (the 8-bit sRGB path and the legends). Renders run two at a time.

    python tools/pixel_digest.py record --tree /tmp/glassray-old \\
        --python .venv/bin/python -o /tmp/digests-old.json
    python tools/pixel_digest.py record --tree . --python .venv/bin/python \\
        -o /tmp/digests-new.json
    python tools/pixel_digest.py compare /tmp/digests-old.json /tmp/digests-new.json

`compare` exits 1 and prints each differing (or missing, or failed) case if
any differ; 0 and "N cases identical" otherwise. Both records must come from
the same machine and OpenGL driver (llvmpipe images differ between Mesa
versions); record the old tree twice to see that it is deterministic.
"""
from __future__ import annotations

import argparse
import hashlib
import json
import os
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

SCENES = ["bench-many", "bench-opaque", "coloured-liquid", "default", "glass-rod-x",
          "glass-sphere", "mirror-ball", "whitted-exact", "whitted-glass"]
# `python -m viewer render --help` at 751b0cf
VIEWS = ["color", "normals", "depth", "objects", "cost", "samples"]
SIZE = "96x54"
UNIFORM = ["--samples", "4"]
ADAPTIVE = ["--samples", "4", "--adaptive"]
EXTRA_SCENES = ["default", "whitted-glass", "coloured-liquid"]
EXTRAS = {"max-depth-2": UNIFORM + ["--max-depth", "2"],
          "seed-3": UNIFORM + ["--seed", "3"],
          "samples-1": ["--samples", "1"]}
# (scene, view, mode) rendered as .png as well
PNGS = [("default", "color", "uniform"), ("default", "color", "adaptive"),
        ("whitted-glass", "normals", "uniform"), ("default", "depth", "uniform"),
        ("coloured-liquid", "objects", "uniform"), ("whitted-glass", "cost", "uniform"),
        ("default", "samples", "adaptive")]


def cases() -> dict[str, tuple[str, list[str], str]]:
    """name -> (scene, extra CLI arguments, output extension)."""
    out: dict[str, tuple[str, list[str], str]] = {}
    for scene in SCENES:
        for view in VIEWS:
            out[f"{scene}/{view}/uniform.npy"] = (scene, ["--view", view] + UNIFORM, ".npy")
        for view in ("color", "samples"):
            out[f"{scene}/{view}/adaptive.npy"] = (scene, ["--view", view] + ADAPTIVE, ".npy")
    for scene in EXTRA_SCENES:
        for name, args in EXTRAS.items():
            out[f"{scene}/color/{name}.npy"] = (scene, ["--view", "color"] + args, ".npy")
    for scene, view, mode in PNGS:
        out[f"{scene}/{view}/{mode}.png"] = (scene, ["--view", view] + (ADAPTIVE if mode == "adaptive" else UNIFORM), ".png")
    return out


def _env(tree: Path) -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = str(tree)          # cwd=tree already puts it first; this is belt and braces
    env["PYTHONDONTWRITEBYTECODE"] = "1"
    return env


def which_viewer(python: str, tree: Path) -> str:
    """The viewer package that `python -m viewer` imports when run in tree."""
    r = subprocess.run([python, "-c", "import viewer; print(viewer.__file__)"], cwd=tree,
                       env=_env(tree), capture_output=True, text=True, check=True)
    return r.stdout.strip()


def render(python: str, tree: Path, scene: str, args: list[str], out: Path,
           backend: str | None) -> dict:
    cmd = [python, "-m", "viewer", "render", scene, "-o", str(out), "--size", SIZE] + args
    if backend:
        cmd += ["--backend", backend]
    r = subprocess.run(cmd, cwd=tree, env=_env(tree), capture_output=True, text=True)
    rec = {"args": [scene, "--size", SIZE] + args, "rc": r.returncode}
    if r.returncode == 0 and out.exists():
        data = out.read_bytes()
        rec["sha256"] = hashlib.sha256(data).hexdigest()
        rec["bytes"] = len(data)
    else:
        rec["error"] = (r.stderr or r.stdout).strip()[-2000:]
    return rec


def record(tree: Path, python: str, output: Path, jobs: int, backend: str | None) -> int:
    tree = tree.resolve()
    imported = Path(which_viewer(python, tree)).resolve()
    if tree not in imported.parents:
        print(f"pixel_digest: {python} in {tree} imports {imported}, not that tree's viewer", file=sys.stderr)
        return 2
    try:
        commit = subprocess.run(["git", "rev-parse", "HEAD"], cwd=tree, capture_output=True,
                                text=True).stdout.strip() or None
    except OSError:
        commit = None
    todo = cases()
    t0 = time.monotonic()
    with tempfile.TemporaryDirectory(prefix="pixel-digest-") as tmp:
        def one(item):
            name, (scene, args, ext) = item
            out = Path(tmp) / (name.replace("/", "_") + ext)
            return name, render(python, tree, scene, args, out, backend)
        with ThreadPoolExecutor(max_workers=jobs) as pool:
            results = {}
            for i, (name, rec) in enumerate(pool.map(one, todo.items()), 1):
                results[name] = rec
                status = rec.get("sha256", "FAILED")[:12]
                print(f"[{i}/{len(todo)}] {name} {status}", flush=True)
    seconds = time.monotonic() - t0
    doc = {"tree": str(tree), "commit": commit, "viewer": str(imported), "python": python,
           "backend": backend, "seconds": round(seconds, 1), "cases": results}
    output.write_text(json.dumps(doc, indent=1, sort_keys=True) + "\n")
    failed = [n for n, r in results.items() if "sha256" not in r]
    print(f"{len(results)} cases in {seconds:.0f} s -> {output}"
          + (f"; {len(failed)} failed: {', '.join(failed)}" if failed else ""))
    return 1 if failed else 0


def compare(a: Path, b: Path) -> int:
    ca = json.loads(a.read_text())["cases"]
    cb = json.loads(b.read_text())["cases"]
    differ = []
    for name in sorted(set(ca) | set(cb)):
        ra, rb = ca.get(name), cb.get(name)
        if ra is None or rb is None:
            differ.append(f"{name}: only in {a if rb is None else b}")
        elif "sha256" not in ra or "sha256" not in rb:
            differ.append(f"{name}: failed in {a if 'sha256' not in ra else b}: "
                          f"{(ra if 'sha256' not in ra else rb).get('error', '')[-200:]}")
        elif ra["args"] != rb["args"]:
            differ.append(f"{name}: different arguments {ra['args']} / {rb['args']}")
        elif ra["sha256"] != rb["sha256"]:
            differ.append(f"{name}: {ra['sha256'][:16]} ({ra['bytes']} bytes) != "
                          f"{rb['sha256'][:16]} ({rb['bytes']} bytes)")
    for line in differ:
        print(line)
    if differ:
        print(f"{len(differ)} of {len(set(ca) | set(cb))} cases differ")
        return 1
    print(f"{len(ca)} cases identical")
    return 0


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = p.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("record", help="render every case in TREE and write their digests")
    r.add_argument("--tree", type=Path, required=True, help="the source tree whose viewer renders")
    r.add_argument("--python", default=sys.executable, help="interpreter (default: this one)")
    r.add_argument("-o", "--output", type=Path, required=True, help="JSON file to write")
    r.add_argument("--jobs", type=int, default=2, help="renders at a time (2)")
    r.add_argument("--backend", choices=["egl", "osmesa"], help="pass --backend to every render")
    c = sub.add_parser("compare", help="compare two digest files")
    c.add_argument("a", type=Path)
    c.add_argument("b", type=Path)
    args = p.parse_args(argv)
    if args.cmd == "record":
        return record(args.tree, args.python, args.output, args.jobs, args.backend)
    return compare(args.a, args.b)


if __name__ == "__main__":
    sys.exit(main())

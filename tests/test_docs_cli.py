"""docs/cli.md against the parser: every option every subcommand's parser
has (except hidden ones) is in that subcommand's section of the document,
and every --flag a section names is an option of that subcommand (or one
the document says belongs elsewhere).  Each check is a function of the
text, so the *_catches_* tests feed it a broken one and see it fail."""

from __future__ import annotations

import argparse
import re
from pathlib import Path

from viewer.cli.commands import build_parser

ROOT = Path(__file__).resolve().parents[1]
DOC = ROOT / "docs" / "cli.md"

#: The heading of each subcommand's section in docs/cli.md.
SECTIONS = {"view": "## The viewer", "render": "## render", "check": "## check", "bench": "## bench",
            "stress": "## stress"}
#: The scene overrides are documented once, in their own section, for view and render.
SHARED = "## Scene overrides"
#: Options every subcommand takes, documented once before the first section.
COMMON = {"--debug"}


def options(sub: str) -> set[str]:
    """The option strings of a subcommand's parser, without -h/--help and
    hidden (help=SUPPRESS) ones."""
    parser = build_parser().subcommands[sub]
    out = set()
    for action in parser._actions:
        if action.help == argparse.SUPPRESS or isinstance(action, argparse._HelpAction):
            continue
        out.update(s for s in action.option_strings)
    return out


def section(text: str, heading: str) -> str:
    start = text.index("\n" + heading + "\n")
    rest = text[start + len(heading) + 2:]
    end = re.search(r"^## ", rest, flags=re.M)
    return rest[:end.start()] if end else rest


def problems(text: str) -> list[str]:
    bad = []
    shared = section(text, SHARED)
    intro = text[:text.index("\n## ")]
    overrides = {"--samples", "--max-depth", "--min-weight", "--camera-position", "--camera-target", "--fov",
                 "--light-position"}
    for sub, heading in SECTIONS.items():
        body = section(text, heading)
        # long flags anywhere (prose, tables, sh blocks), short ones in code spans
        named = set(re.findall(r"(?<![\w-])(--[a-z][a-z0-9-]*)", body)) | set(re.findall(r"`(-[a-z])\b", body))
        have = options(sub)
        for opt in sorted(have):
            where = shared if opt in overrides and sub in ("view", "render") else intro if opt in COMMON else body
            if not re.search(rf"`{re.escape(opt)}[ `=,\\]", where) and f"`{opt}`" not in where:
                bad.append(f"{sub}: {opt} is not documented")
        for flag in sorted(named - have):
            if flag == "--help":
                continue
            bad.append(f"{sub}: docs/cli.md names {flag}, which {sub} does not take")
    return bad


def test_every_option_of_the_parser_is_documented_and_nothing_else():
    assert problems(DOC.read_text(encoding="utf-8")) == []


def test_the_check_catches_a_missing_option():
    text = DOC.read_text(encoding="utf-8")
    broken = text.replace("| `--seed N` |", "| seed |")
    assert problems(broken) == ["render: --seed is not documented"]


def test_the_check_catches_an_option_the_parser_does_not_have():
    text = DOC.read_text(encoding="utf-8")
    broken = text.replace("## check\n", "## check\n\nIt takes `--verbose`.\n")
    assert "check: docs/cli.md names --verbose, which check does not take" in problems(broken)


def test_every_subcommand_has_a_section():
    subs = set(build_parser().subcommands)
    assert subs == set(SECTIONS), subs

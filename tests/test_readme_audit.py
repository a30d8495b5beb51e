"""The README against the program, mechanically (no rendering, no processes).

- every relative link and image (``docs/*.png``, ``docs/cli.md``) names a
  file of the repository;
- every ``(#anchor)`` link matches a heading by GitHub's slug rules;
- every ``glassray ...`` command shown (``sh`` blocks and inline code) names a
  subcommand, and every ``--flag`` it uses is an option of that subcommand in
  viewer/cli/'s parser; a complete command (no placeholder such as
  ``[SCENE]``, ``OUT`` or ``E``) is parsed whole, values included;
- the flags listed in the prose for one subcommand ("Options of `render`",
  the Benchmark and Numerical stability sections) are that subcommand's;
- every other backticked ``--flag`` is an option of some subcommand, of the
  test suite (``pytest --update-goldens``) or of the tool it is given to;
- ``python tools/NAME.py`` names a script in tools/;
- the README's controls table holds every row of the spec's.

Each check is a function of the README's text, so the ``*_catches_*`` tests
feed it a broken string and see it fail.  ``README_AUDIT_PATH=FILE`` points
the checks at another copy of the README (to see them fail on a broken one).
"""

from __future__ import annotations

import contextlib
import io
import os
import re
import shlex
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
README = Path(os.environ.get("README_AUDIT_PATH") or ROOT / "README.md")
SPEC_CLI = ROOT / "docs" / "cli.md"          # the spec's copy shipped with the repository

SUBCOMMANDS = ("view", "render", "check", "bench", "stress")


#: The user's documents, which the README links to and which get the same
#: checks as the README (docs/notes/ are lab notebooks, not checked).
DOCS = ("cli.md", "api.md", "scene-format.md", "how-it-works.md", "performance.md", "accuracy.md", "design.md")


@pytest.fixture(scope="module")
def readme() -> str:
    return README.read_text(encoding="utf-8")


@pytest.fixture(scope="module", params=DOCS)
def doc(request) -> tuple[str, str]:
    """(name, text) of one of the docs."""
    return f"docs/{request.param}", (ROOT / "docs" / request.param).read_text(encoding="utf-8")


# ---------------------------------------------------------------- text helpers


def _line_of(text: str, pos: int) -> int:
    return text.count("\n", 0, pos) + 1


def prose(text: str) -> str:
    """The text with fenced code blocks blanked out (newlines kept, so
    positions still give line numbers)."""
    return re.sub(r"^```.*?^```[ \t]*$", lambda m: "\n" * m.group(0).count("\n"), text, flags=re.S | re.M)


def code_spans(text: str) -> list[tuple[int, str]]:
    """(line, content) of every inline code span outside fenced blocks,
    whitespace (line breaks too) collapsed to one space."""
    p = prose(text)
    return [(_line_of(p, m.start()), " ".join(m.group(1).split())) for m in re.finditer(r"`([^`]+)`", p)]


def sh_lines(text: str) -> list[tuple[int, str]]:
    """(line, command) of every line of a ``sh`` block, comments dropped; a
    ``$ `` prompt marks a command whose following lines are its output."""
    out = []
    lines = text.splitlines()
    i = 0
    while i < len(lines):
        if re.match(r"^```(sh|bash|shell|console)\s*$", lines[i]):
            i += 1
            prompted = False
            while i < len(lines) and not lines[i].startswith("```"):
                line = lines[i]
                if line.startswith("$ "):
                    prompted = True
                    out.append((i + 1, line[2:].split(" #")[0].strip()))
                elif not prompted and line.strip() and not line.lstrip().startswith("#"):
                    out.append((i + 1, line.split(" #")[0].strip()))
                i += 1
        i += 1
    return out


def headings(text: str) -> list[str]:
    return [m.group(1).strip() for m in re.finditer(r"^#{1,6}[ \t]+(.+?)[ \t#]*$", prose(text), flags=re.M)]


def github_slug(heading: str) -> str:
    """GitHub's anchor for a heading: lower case, markup and punctuation other
    than '-' and '_' dropped, each space a '-'."""
    h = re.sub(r"`|\*\*|__", "", heading)
    h = re.sub(r"\[([^\]]*)\]\([^)]*\)", r"\1", h)       # a link keeps its text
    h = h.strip().lower()
    h = re.sub(r"[^\w\- ]", "", h)
    return h.replace(" ", "-")


def anchors(text: str) -> set[str]:
    seen: dict[str, int] = {}
    out = set()
    for h in headings(text):
        s = github_slug(h)
        n = seen.get(s, 0)
        out.add(s if n == 0 else f"{s}-{n}")
        seen[s] = n + 1
    return out


def links(text: str) -> list[tuple[int, str]]:
    """(line, target) of every markdown link and image outside code; the
    link text may span lines."""
    p = prose(text)
    p = re.sub(r"`[^`]*`", lambda m: re.sub(r"[^\n]", " ", m.group(0)), p)   # no links inside code spans
    return [(_line_of(p, m.start()), m.group(1)) for m in re.finditer(r"\]\(([^)\s]+)(?:\s+\"[^\"]*\")?\)", p)]


# ---------------------------------------------------------------- checks (each returns its problems)


def check_link_targets(text: str, root: Path = ROOT, name: str = "README") -> list[str]:
    """Every relative link names a file (relative to `root`, the folder of
    the document), and a link to a heading of another markdown file
    (``docs/benchmark.md#results``, ``../README.md#benchmark``) names one
    of its headings."""
    bad = []
    for line, target in links(text):
        if target.startswith("#") or re.match(r"^[a-z][a-z0-9+.-]*:", target):
            continue
        path, _, anchor = target.partition("#")
        if not (root / path).exists():
            bad.append(f"{name}:{line}: link to {target}: no such file")
        elif anchor and path.endswith(".md") and anchor not in anchors((root / path).read_text(encoding="utf-8")):
            bad.append(f"{name}:{line}: link to {target}: no heading of {path} has that anchor")
    return bad


def check_anchor_links(text: str, name: str = "README") -> list[str]:
    known = anchors(text)
    return [f"{name}:{line}: link to {target}: no heading has that anchor"
            for line, target in links(text) if target.startswith("#") and target[1:] not in known]


def _parser():
    from viewer.cli import build_parser

    return build_parser()


PLACEHOLDER = re.compile(r"^(\[.*\]|[A-Z]+|\.\.\.|[a-z]+\|[a-z|]+)$")


def _split_command(cmd: str) -> list[str] | None:
    """argv after ``glassray`` (or ``python -m viewer``), None if not one."""
    try:
        words = shlex.split(cmd)
    except ValueError:
        words = cmd.split()
    if words[:1] == ["glassray"]:
        return words[1:]
    if words[:3] == ["python", "-m", "viewer"]:
        return words[3:]
    return None


def _subcommand(argv: list[str]) -> str:
    first = next((a for a in argv if not a.startswith("-")), None)
    return first if first in SUBCOMMANDS else "view"


def _option_strings(parser, sub: str) -> set[str]:
    return set(parser.subcommands[sub]._option_string_actions)


def _flags(words) -> list[str]:
    """The --flags among words; ``--vsync/--no-vsync`` is two."""
    return [f.split("=")[0] for w in words for f in w.split("/") if re.match(r"^--[a-z]", f)]


def check_commands(commands: list[tuple[int, str, bool]], parser=None) -> list[str]:
    """Each (line, command, inline): the subcommand exists, each --flag is
    its option (spelt out, not an abbreviation), and a complete command
    parses whole (values in range, nothing left over).  Inline code that
    ends in an option names that option (`glassray bench --peer`): it is
    parsed without it."""
    from viewer.cli.commands import normalise_argv

    parser = parser or _parser()
    top = set(parser._option_string_actions)
    bad = []
    for line, cmd, inline in commands:
        argv = _split_command(cmd)
        if argv is None:
            continue
        if argv == ["..."]:
            continue
        words = [w for w in argv if w not in ("[view]",)]
        if any(w in ("--version", "--help", "-h") for w in words) and _subcommand(words) == "view" \
                and not any(w in SUBCOMMANDS for w in words):
            unknown = [f for f in _flags(words) if f not in top]
            bad += [f"README:{line}: `{cmd}`: glassray has no option {f}" for f in unknown]
            continue
        sub = _subcommand(words)
        options = _option_strings(parser, sub)
        unknown = [f for f in _flags(words) if f not in options]
        bad += [f"README:{line}: `{cmd}`: glassray {sub} has no option {f}" for f in unknown]
        placeholders = any(PLACEHOLDER.match(w) for w in words if w not in SUBCOMMANDS)
        incomplete = sub == "render" and not any(w in ("-o", "--output") or w.startswith("--output=") for w in words)
        if unknown or placeholders or incomplete:
            continue
        if inline and words and words[-1].startswith("--") and "=" not in words[-1]:
            words = words[:-1]
        err = io.StringIO()
        try:
            with contextlib.redirect_stderr(err):
                _args, extra = parser.parse_known_args(normalise_argv(words))
        except SystemExit:
            bad.append(f"README:{line}: `{cmd}`: rejected: {err.getvalue().strip().splitlines()[-1]}")
            continue
        if extra:
            bad.append(f"README:{line}: `{cmd}`: unrecognized arguments: {' '.join(extra)}")
    return bad


def readme_commands(text: str) -> list[tuple[int, str]]:
    """Every glassray command the README shows: the lines of its sh blocks,
    and inline code that starts with ``glassray`` (or with a subcommand and
    a flag: ``render --adaptive --samples N``)."""
    out = [(line, cmd, False) for line, cmd in sh_lines(text) if _split_command(cmd) is not None]
    for line, span in code_spans(text):
        if re.match(r"^(glassray|python -m viewer)( |$)", span):
            out.append((line, span, True))
        elif re.match(rf"^({'|'.join(SUBCOMMANDS)}) --", span):
            out.append((line, f"glassray {span}", True))
    return out


#: Prose that lists one subcommand's options: (regex of where it starts,
#: regex of where it ends, subcommand, required).  Spans inside that start
#: with a command of their own are checked as commands instead.
OPTION_REGIONS = (
    (r"Options of `render`:", r"\n\n", "render", False),     # (docs/cli.md: tests/test_docs_cli.py)
    (r"Options of `view`:", r"\n\n", "view", False),
    (r"Options: `--adaptive", r"\n\n", "render", False),        # Adaptive anti-aliasing
    (r"Other options: `--reference", r"\n\n", "bench", False),  # Benchmark
    (r"It writes `contact-sheet.png`", r"\n\n", "stress", False),  # Numerical stability
)


def check_option_regions(text: str, parser=None) -> list[str]:
    parser = parser or _parser()
    p = prose(text)
    bad = []
    for start, end, sub, required in OPTION_REGIONS:
        m = re.search(start, p, flags=re.M)
        if m is None:
            if required:
                bad.append(f"README: no text matching {start!r} (the list of {sub}'s options)")
            continue
        e = re.compile(end, flags=re.M).search(p, m.end())
        region = p[m.start():e.start() if e else len(p)]
        options = _option_strings(parser, sub)
        for sm in re.finditer(r"`([^`]+)`", region):
            span = " ".join(sm.group(1).split())
            if re.match(rf"^(glassray|python|pytest|{'|'.join(SUBCOMMANDS)})\b", span):
                continue
            for f in _flags(span.split()):
                if f not in options:
                    line = _line_of(p, m.start() + sm.start())
                    bad.append(f"README:{line}: `{span}` (in the options of {sub}): glassray {sub} has no option {f}")
    return bad


def check_every_flag(text: str, parser=None) -> list[str]:
    """Any backticked --flag is an option of a subcommand or of glassray,
    of pytest's conftest (``pytest --flag``) or of the tool it goes to
    (``python tools/NAME.py --flag``)."""
    parser = parser or _parser()
    known = set(parser._option_string_actions)
    for sub in SUBCOMMANDS:
        known |= _option_strings(parser, sub)
    conftest = (ROOT / "tests" / "conftest.py").read_text()
    bad = []
    for line, span in code_spans(text):
        flags = _flags(span.split())
        if not flags:
            continue
        m = re.match(r"^python (tools/[\w.-]+\.py)", span)
        if m:
            src = ROOT / m.group(1)
            missing = [f for f in flags if not src.exists() or f'"{f}"' not in src.read_text()]
            bad += [f"README:{line}: `{span}`: {m.group(1)} takes no {f}" for f in missing]
            continue
        if span.startswith("pytest"):
            bad += [f"README:{line}: `{span}`: no pytest option {f} in tests/conftest.py"
                    for f in flags if f'"{f}"' not in conftest]
            continue
        bad += [f"README:{line}: `{span}`: no glassray subcommand has {f}" for f in flags if f not in known]
    return bad


def check_tool_scripts(text: str, root: Path = ROOT) -> list[str]:
    found = {(line, m) for line, span in code_spans(text) for m in re.findall(r"\btools/[\w-]+\.py", span)}
    found |= {(line, m) for line, cmd in sh_lines(text) for m in re.findall(r"\btools/[\w-]+\.py", cmd)}
    return [f"README:{line}: {path}: no such script" for line, path in sorted(found) if not (root / path).exists()]


def _table_rows(text: str, header: str) -> list[str]:
    lines = text.splitlines()
    i = next((k for k, l in enumerate(lines) if l.strip() == header), None)
    if i is None:
        return []
    rows = []
    for l in lines[i + 2:]:
        if not l.startswith("|"):
            break
        rows.append(l.strip())
    return rows


def check_controls_table(text: str, spec: str) -> list[str]:
    header = "| input | effect |"
    spec_rows = _table_rows(spec, header)
    ours = set(_table_rows(text, header))
    if not spec_rows:
        return ["spec: no controls table"]
    return [f"README: the controls table lacks the spec's row {r}" for r in spec_rows if r not in ours]


# ---------------------------------------------------------------- the README as it is


def test_every_linked_file_and_image_exists(readme):
    assert check_link_targets(readme) == []


def test_every_anchor_link_matches_a_heading(readme):
    assert check_anchor_links(readme) == []


def test_every_glassray_command_shown_is_accepted_by_its_parser(readme):
    commands = readme_commands(readme)
    assert len(commands) > 12            # the extraction found the README's commands
    assert check_commands(commands) == []


def test_the_options_listed_for_a_subcommand_are_its_own(readme):
    assert check_option_regions(readme) == []


def test_every_backticked_flag_is_an_option_somewhere(readme):
    assert check_every_flag(readme) == []


def test_every_tool_script_named_exists(readme):
    assert check_tool_scripts(readme) == []


def test_the_controls_table_holds_every_row_of_the_spec(readme):
    assert check_controls_table(readme, SPEC_CLI.read_text(encoding="utf-8")) == []


# ---------------------------------------------------------------- the docs the README links to


def test_the_readme_links_every_doc(readme):
    assert [d for d in DOCS if f"(docs/{d}" not in readme] == []


def test_every_link_of_a_doc_names_a_file_and_heading(doc):
    name, text = doc
    assert check_link_targets(text, ROOT / "docs", name) == []
    assert check_anchor_links(text, name) == []


def test_every_glassray_command_of_a_doc_is_accepted(doc):
    assert check_commands(readme_commands(doc[1])) == []


def test_every_flag_and_tool_of_a_doc_exists(doc):
    assert check_every_flag(doc[1]) == []
    assert check_tool_scripts(doc[1]) == []


# ---------------------------------------------------------------- each check fails on a broken README


def test_link_check_catches_a_missing_image():
    assert check_link_targets("![shot](docs/no-such-picture.png) and [ok](docs/cli.md)\n") == [
        "README:1: link to docs/no-such-picture.png: no such file"]


def test_link_check_catches_a_wrong_heading_of_another_file_and_resolves_from_the_docs_folder():
    text = "[a](../README.md#benchmark) [b](../README.md#no-such-section) [c](cli.md) [d](docs/cli.md)\n"
    assert check_link_targets(text, ROOT / "docs", "docs/x.md") == [
        "docs/x.md:1: link to ../README.md#no-such-section: no heading of ../README.md has that anchor",
        "docs/x.md:1: link to docs/cli.md: no such file"]


def test_anchor_check_catches_a_wrong_anchor_and_follows_github_slugs():
    text = ("# Tool\n## Against a renderer (Mitsuba 3)\n## Results\n### Results\n"
            "see [it](#against-a-renderer-mitsuba-3), [r](#results-1), [multi\nline](#measured-speed)\n"
            "```sh\n# not a heading\n```\n[x](#not-a-heading)\n")
    assert check_anchor_links(text) == ["README:6: link to #measured-speed: no heading has that anchor",
                                        "README:10: link to #not-a-heading: no heading has that anchor"]


def test_command_check_catches_an_unknown_flag_a_bad_value_and_an_unknown_option_of_another_subcommand():
    text = ("```sh\nglassray render -o a.png --sample 4   # typo\n"
            "glassray render -o a.png --size 0x5\nglassray stress --repeat 3\n"
            "$ glassray check\noutput --not-a-flag\n```\n"
            "Run `glassray bench --quick\n--frobnicate` or `render --adaptive --samples N`, see `glassray bench --peer`.\n")
    bad = check_commands(readme_commands(text))
    assert len(bad) == 4, bad
    assert "glassray render has no option --sample" in bad[0]
    assert "README:3:" in bad[1] and "0x5" in bad[1]
    assert "glassray stress has no option --repeat" in bad[2]
    assert "README:8:" in bad[3] and "--frobnicate" in bad[3]


def test_option_region_check_catches_a_flag_of_another_subcommand():
    text = ("Options of `render`: `--size WxH`, `--vsync/--no-vsync`.\n\nOptions of `view`: `--no-vsync`.\n\n"
            "Other options: `--reference-samples N`, `--naive`, and `render --adaptive`.\n\n"
            "It writes `contact-sheet.png` (`--columns N`)\n")
    bad = check_option_regions(text)
    assert len(bad) == 3 and "--vsync" in bad[0] and "--no-vsync" in bad[1] and "--naive" in bad[2], bad
    assert check_option_regions("Options of `view`: `--size WxH`.\n") == []     # the other lists are optional


def test_flag_check_catches_an_unknown_flag_in_prose():
    bad = check_every_flag("`--max-depth N`, `--no-such-flag`, `pytest --update-goldens`, "
                           "`python tools/adaptive_steps.py --glass`, `python tools/adaptive_steps.py --gloss`\n")
    assert len(bad) == 2 and "--no-such-flag" in bad[0] and "--gloss" in bad[1], bad


def test_tool_check_catches_a_missing_script():
    assert check_tool_scripts("`python tools/no_such_tool.py`\n") == [
        "README:1: tools/no_such_tool.py: no such script"]


def test_controls_check_catches_a_missing_row():
    spec = "| input | effect |\n|---|---|\n| Esc | quit |\n| Tab | panel |\n"
    assert check_controls_table("| input | effect |\n|---|---|\n| Esc | quit |\n", spec) == [
        "README: the controls table lacks the spec's row | Tab | panel |"]

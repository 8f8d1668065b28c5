"""The documentation points at things that exist (docs/testing.md, "The docs check").

For every tracked ``*.md`` file of the repository:

* every relative link and image -- ``[text](target)``, ``![alt](target)``, ``[name]: target``,
  ``<img src=...>``, ``<a href=...>`` -- names an existing file or directory (relative to the
  Markdown file), and an ``#anchor`` into a Markdown file names one of its headings (GitHub's
  heading ids) or an ``<a name=...>``/``id=...`` in it;
* in code spans and in shell code blocks (fences without a language, or ``bash``, ``sh``,
  ``shell``, ``console``), every ``roslaunch PKG FILE`` / ``rostest PKG FILE`` names a file of
  that package, every ``rosrun PKG NODE`` an executable of that package, and every
  ``make [-C DIR] TARGET`` a target of that Makefile.

What is not checked, on purpose (the skip rules, all here):

* placeholders: a package, file or target word with ``< > $ * { } [ ] |`` or ``...`` in it, or
  written in capitals only (``PKG``, ``FILE``, ``OUT_PREFIX``);
* packages that are not ours (``tf``, ``rviz``, a camera driver): only this workspace's packages,
  and any ``chefbot_*`` name (a typo of ours), are checked;
* the book's own names that this workspace replaces (:data:`BOOK_PACKAGES`, :data:`BOOK_FILES`),
  which the README's book-command table quotes;
* web links (``http:``, ``https:``, ``mailto:`` ...).

A failure names ``file:line`` and the broken reference.
"""
from __future__ import annotations

import os
import re
import subprocess
from dataclasses import dataclass, field
from pathlib import Path
from urllib.parse import unquote
from xml.etree import ElementTree

import pytest

ROOT = Path(__file__).resolve().parents[2]

# The book's packages that this workspace replaces (quoted in the README's book-command table).
BOOK_PACKAGES = {"chefbot_gazebo"}
# The book's launch files of packages we have, under another name here (the same table).
BOOK_FILES = {("chefbot_description", "view_robot.launch"), ("chefbot_bringup", "3dsensor_astra.launch")}

SHELL_FENCES = {"", "bash", "sh", "shell", "console"}
COMMANDS = {"roslaunch", "rosrun", "rostest", "make"}
PLACEHOLDER_CHARS = set("<>${}[]*|")
SKIP_DIRS = {".git", ".venv", "build", "devel", "install", "node_modules"}


# ------------------------------------------------------------------ the workspace
@dataclass
class Workspace:
    """The files the checker resolves references against."""

    root: Path
    md_files: list[Path]                             # relative to root
    packages: dict[str, Path] = field(default_factory=dict)   # package name -> directory (absolute)

    @classmethod
    def scan(cls, root: Path) -> Workspace:
        """``git ls-files`` of ``root`` when it is a repository with tracked files, else a walk."""
        files = _git_files(root)
        if files is None:
            files = [p.relative_to(root) for p in root.rglob("*")
                     if p.is_file() and not SKIP_DIRS & set(p.relative_to(root).parts)]
        md = sorted(f for f in files if f.suffix == ".md" and (root / f).is_file())
        packages = {}
        for f in files:
            if f.name == "package.xml" and len(f.parts) == 2 and (root / f).is_file():
                name = ElementTree.parse(root / f).getroot().findtext("name", "").strip()
                if name:
                    packages[name] = root / f.parent
        return cls(root, md, packages)


def _git_files(root: Path) -> list[Path] | None:
    try:
        out = subprocess.run(["git", "ls-files", "-z"], cwd=root, capture_output=True, text=True, check=True).stdout
    except (OSError, subprocess.CalledProcessError):
        return None
    if Path(subprocess.run(["git", "rev-parse", "--show-toplevel"], cwd=root, capture_output=True,
                           text=True, check=False).stdout.strip() or "/nonexistent").resolve() != root.resolve():
        return None   # root is inside another repository (a tmp tree in a checkout)
    files = [Path(p) for p in out.split("\0") if p]
    return files or None


# ------------------------------------------------------------------ Markdown scanning
FENCE = re.compile(r"^\s{0,3}(`{3,}|~{3,})\s*([\w+-]*)")
CODE_SPAN = re.compile(r"(?<!`)(`+)(?!`)(.+?)(?<!`)\1(?!`)", re.S)
LINK = re.compile(r"!?\[(?:[^\[\]]|\[[^\[\]]*\])*\]\(\s*<?([^)\s>]*)>?(?:\s+[\"'(][^)]*)?\)")
REF_DEF = re.compile(r"^\s{0,3}\[[^\]]+\]:\s*<?(\S+?)>?(?:\s.*)?$")
HTML_REF = re.compile(r"<(?:img|a|source)\b[^>]*?\s(?:src|href)\s*=\s*[\"']([^\"']+)[\"']", re.I)
HTML_ID = re.compile(r"<[a-z]+\b[^>]*?\s(?:name|id)\s*=\s*[\"']([^\"']+)[\"']", re.I)
HEADING = re.compile(r"^\s{0,3}(#{1,6})\s+(.*?)\s*#*\s*$")
SCHEME = re.compile(r"^[a-zA-Z][a-zA-Z0-9+.-]*:")


@dataclass
class Line:
    number: int
    text: str          # prose with code spans blanked out ("" inside code blocks)
    code: list[str]    # code span texts, or the (joined) shell line of a code block


def scan_markdown(text: str) -> list[Line]:
    """The lines of a Markdown text, split into prose and code (shell code only for blocks).

    Code spans may run over a line break inside a paragraph; the span belongs to its first line.
    """
    out: list[Line] = []
    fence: tuple[str, bool] | None = None     # (marker, shell?) while inside a code block
    pending = ""                              # a shell line continued with a backslash
    pending_no = 0
    paragraph: list[tuple[int, str]] = []

    def flush() -> None:
        if paragraph:
            out.extend(_prose(paragraph))
            paragraph.clear()

    for no, raw in enumerate(text.splitlines(), start=1):
        m = FENCE.match(raw)
        if fence is None and m:
            flush()
            fence = (m.group(1), m.group(2).lower() in SHELL_FENCES)
            continue
        if fence is not None:
            if raw.strip().startswith(fence[0][0] * len(fence[0])) and not raw.strip().strip(fence[0][0]):
                fence, pending = None, ""
                continue
            if fence[1]:
                line = _strip_comment(raw)
                if pending:
                    line, no = pending + " " + line, pending_no
                if line.rstrip().endswith("\\"):
                    pending, pending_no = line.rstrip()[:-1], no
                    continue
                pending = ""
                out.append(Line(no, "", [line]))
            continue
        if raw.strip():
            paragraph.append((no, raw))
        else:
            flush()
    flush()
    return out


def _prose(paragraph: list[tuple[int, str]]) -> list[Line]:
    """The lines of one paragraph with their code spans (found across line breaks) blanked out."""
    joined = "\n".join(raw for _, raw in paragraph)
    starts = [0]
    for _, raw in paragraph[:-1]:
        starts.append(starts[-1] + len(raw) + 1)
    spans: dict[int, list[str]] = {}
    for m in CODE_SPAN.finditer(joined):
        first = max(i for i, s in enumerate(starts) if s <= m.start())
        spans.setdefault(first, []).append(m.group(2).replace("\n", " "))
    blanked = CODE_SPAN.sub(lambda m: " " + "\n" * m.group(0).count("\n"), joined).split("\n")
    return [Line(no, blanked[i], spans.get(i, [])) for i, (no, _) in enumerate(paragraph)]


def _strip_comment(line: str) -> str:
    return re.sub(r"(^|\s)#.*$", "", line)


def slug(heading: str) -> str:
    """GitHub's id of a heading: markup dropped, lower case, punctuation removed, spaces to '-'."""
    text = re.sub(r"!?\[([^\]]*)\]\([^)]*\)", r"\1", heading)   # links -> their text
    text = re.sub(r"<[^>]+>", "", text).replace("`", "").replace("*", "")
    text = re.sub(r"[^\w\- ]", "", text.strip().lower())
    return text.replace(" ", "-")


def anchors(text: str) -> set[str]:
    """Heading ids (with GitHub's -1, -2 for repeats) and explicit name/id attributes of a Markdown text."""
    seen: dict[str, int] = {}
    ids = set()
    fence = None
    for raw in text.splitlines():
        m = FENCE.match(raw)
        if m and (fence is None or raw.strip().startswith(fence)):
            fence = None if fence else m.group(1)
            continue
        if fence:
            continue
        ids |= set(HTML_ID.findall(raw))
        h = HEADING.match(raw)
        if h:
            base = slug(h.group(2))
            n = seen.get(base, 0)
            seen[base] = n + 1
            ids.add(base if n == 0 else f"{base}-{n}")
    return ids


# ------------------------------------------------------------------ links
def link_targets(line: Line) -> list[str]:
    text = line.text
    return LINK.findall(text) + HTML_REF.findall(text) + [m.group(1) for m in [REF_DEF.match(text)] if m]


def check_links(ws: Workspace, rel: Path, text: str) -> list[str]:
    """Problems ``file:line: ...`` of the links and images of one Markdown text (``rel`` to the root)."""
    problems = []
    here = (ws.root / rel).parent
    for line in scan_markdown(text):
        for target in link_targets(line):
            if not target or SCHEME.match(target) or target.startswith("//"):
                continue
            path, _, anchor = target.partition("#")
            dest = (here / unquote(path)).resolve() if path else (ws.root / rel).resolve()
            where = f"{rel}:{line.number}"
            if not dest.exists():
                problems.append(f"{where}: broken link '{target}' (no file {_show(ws, dest)})")
            elif anchor and dest.suffix == ".md" and dest.is_file():
                if anchor not in anchors(dest.read_text(encoding="utf-8", errors="replace")):
                    problems.append(f"{where}: broken link '{target}' (no heading '#{anchor}' in {_show(ws, dest)})")
    return problems


def _show(ws: Workspace, p: Path) -> str:
    try:
        return str(p.relative_to(ws.root.resolve()))
    except ValueError:
        return str(p)


# ------------------------------------------------------------------ commands
def placeholder(word: str) -> bool:
    """A word standing for something the reader fills in (see the module doc)."""
    return (bool(PLACEHOLDER_CHARS & set(word)) or "..." in word or "…" in word
            or bool(re.fullmatch(r"[A-Z][A-Z0-9_]*", word)))


def commands(code: str) -> list[tuple[str, list[str]]]:
    """``(command, arguments)`` for every roslaunch / rosrun / rostest / make in a piece of shell code."""
    found = []
    for segment in re.split(r"&&|\|\||[;|()`]", code):
        words = [w.strip("'\"") for w in segment.split()]
        for i, w in enumerate(words):
            # not the value of a long option (`run_tests.py --only rostest`)
            if w in COMMANDS and not (i and words[i - 1].startswith("--") and "=" not in words[i - 1]):
                found.append((w, words[i + 1:]))
                break
    return found


def makefile_targets(makefile: Path) -> set[str]:
    targets = set()
    for raw in makefile.read_text(encoding="utf-8", errors="replace").splitlines():
        m = re.match(r"^([^\s:#=][^:=#]*?)\s*::?(?!=)", raw)
        if m and not raw.startswith("\t"):
            targets |= set(m.group(1).split())
    return targets


def check_command(ws: Workspace, cmd: str, args: list[str]) -> str | None:
    """What is wrong with one command, or None (also for commands the checker skips)."""
    if cmd == "make":
        directory, targets, skip = ws.root, [], False
        for i, a in enumerate(args):
            if skip:
                skip = False
            elif a == "-C" and i + 1 < len(args):
                directory, skip = ws.root / args[i + 1], True
            elif a.startswith("-C") and len(a) > 2:
                directory = ws.root / a[2:]
            elif a.startswith("--directory="):
                directory = ws.root / a.split("=", 1)[1]
            elif a in ("-f", "-j", "-l", "-o", "-W", "-I"):
                skip = True
            elif not a.startswith("-") and "=" not in a:
                targets.append(a)
        if any(placeholder(t) for t in targets) or placeholder(str(directory.relative_to(ws.root))):
            return None
        makefile = next((directory / n for n in ("GNUmakefile", "makefile", "Makefile")
                         if (directory / n).is_file()), None)
        if makefile is None:
            return f"no Makefile in {_show(ws, directory)}"
        missing = [t for t in targets if t not in makefile_targets(makefile)]
        return f"no target {', '.join(missing)} in {_show(ws, makefile)}" if missing else None

    words, skip = [], False
    for a in args:                           # positional words: no options, no name:=value
        if skip:
            skip = False
        elif a in ("-p", "--port", "--args", "--pid", "--prefix"):
            skip = True
        elif not a.startswith("-") and ":=" not in a:
            words.append(a)
    if not words:
        return None
    if cmd in ("roslaunch", "rostest") and (words[0].endswith((".launch", ".test", ".xml")) or "/" in words[0]):
        if placeholder(words[0]):
            return None
        return None if (ws.root / words[0]).is_file() else f"no file {words[0]}"
    if len(words) < 2:
        return None
    pkg, name = words[0], words[1]
    if placeholder(pkg) or placeholder(name):
        return None
    if pkg not in ws.packages:
        if pkg.startswith("chefbot_") and pkg not in BOOK_PACKAGES:
            return f"no package {pkg} in this workspace"
        return None
    if (pkg, name) in BOOK_FILES:
        return None
    pkg_dir = ws.packages[pkg]
    hits = [p for p in pkg_dir.rglob(name) if p.is_file() and not SKIP_DIRS & set(p.relative_to(ws.root).parts)]
    if cmd == "rosrun":
        if not any(os.access(p, os.X_OK) for p in hits):
            return f"no executable {name} in package {pkg} ({_show(ws, pkg_dir)})"
    elif not hits:
        return f"no file {name} in package {pkg} ({_show(ws, pkg_dir)})"
    return None


def check_commands(ws: Workspace, rel: Path, text: str) -> list[str]:
    """Problems ``file:line: ...`` of the commands in the code of one Markdown text."""
    problems = []
    for line in scan_markdown(text):
        for code in line.code:
            for cmd, args in commands(code):
                why = check_command(ws, cmd, args)
                if why:
                    shown = " ".join([cmd, *args])
                    problems.append(f"{rel}:{line.number}: '{shown[:100]}': {why}")
    return problems


# ------------------------------------------------------------------ the real tree
WORKSPACE = Workspace.scan(ROOT)


def _read(rel: Path) -> str:
    return (ROOT / rel).read_text(encoding="utf-8", errors="replace")


def test_markdown_files_found() -> None:
    assert Path("README.md") in WORKSPACE.md_files
    assert {"chefbot_common", "chefbot_firmware", "chefbot_tests"} <= set(WORKSPACE.packages)


@pytest.mark.parametrize("rel", WORKSPACE.md_files, ids=str)
def test_links_resolve(rel: Path) -> None:
    problems = check_links(WORKSPACE, rel, _read(rel))
    assert not problems, "\n".join(problems)


@pytest.mark.parametrize("rel", WORKSPACE.md_files, ids=str)
def test_commands_name_existing_files(rel: Path) -> None:
    problems = check_commands(WORKSPACE, rel, _read(rel))
    assert not problems, "\n".join(problems)


# ------------------------------------------------------------------ the checker itself
def test_a_broken_link_in_a_copy_of_the_readme_fails() -> None:
    """The README as it is, plus one bad link and one bad command: exactly those two are named."""
    text = _read(Path("README.md"))
    n = len(text.splitlines())
    broken = text + "\nSee [the guide](docs/no-such-page.md).\n\n```bash\nmake demo-fast\n```\n"
    links = check_links(WORKSPACE, Path("README.md"), broken)
    cmds = check_commands(WORKSPACE, Path("README.md"), broken)
    assert f"README.md:{n + 2}: broken link 'docs/no-such-page.md' (no file docs/no-such-page.md)" in links
    assert any(p.startswith(f"README.md:{n + 5}: 'make demo-fast': no target demo-fast") for p in cmds), cmds


@pytest.fixture
def tree(tmp_path: Path) -> Workspace:
    """A small workspace: package foo_pkg (a launch file, a node, a test file), a Makefile, docs/."""
    pkg = tmp_path / "foo"
    (pkg / "launch").mkdir(parents=True)
    (pkg / "nodes").mkdir()
    (pkg / "test").mkdir()
    (pkg / "package.xml").write_text("<package format='2'><name>foo_pkg</name></package>")
    (pkg / "launch" / "run.launch").write_text("<launch/>")
    (pkg / "test" / "it.test").write_text("<launch/>")
    node = pkg / "nodes" / "talker"
    node.write_text("#!/bin/sh\n")
    node.chmod(0o755)
    (pkg / "nodes" / "not_executable").write_text("")
    (pkg / "README.md").write_text("# Foo\n\n## Nodes\n\n### talker (`rosrun`)\n\n## Nodes\n")
    (tmp_path / "Makefile").write_text("VAR := 1\n.PHONY: demo test\ndemo: setup\n\t@echo $(VAR)\ntest:\nsetup:\n")
    (tmp_path / "sub").mkdir()
    (tmp_path / "sub" / "Makefile").write_text("all:\nsketch: all\n")
    (tmp_path / "docs").mkdir()
    (tmp_path / "docs" / "a.md").write_text("# A\n")
    (tmp_path / "img.png").write_bytes(b"")
    return Workspace.scan(tmp_path)


def _check(ws: Workspace, text: str) -> list[str]:
    (ws.root / "docs" / "t.md").write_text(text)
    return check_links(ws, Path("docs/t.md"), text) + check_commands(ws, Path("docs/t.md"), text)


def test_checker_accepts_good_references(tree: Workspace) -> None:
    text = "\n".join([
        "# T", "",
        "[a](a.md), [a's title](a.md#a), [up](../foo/README.md#talker-rosrun), [dup](../foo/README.md#nodes-1),",
        "![img](../img.png) <img src=\"../img.png\" width=3> [dir](../foo/) [web](https://example.com/x.md)",
        "[self](#t) [`code` text](a.md)", "",
        "[ref]: ../foo/package.xml", "",
        "A code span over a line break: `Cannot load command parameter",
        "[robot_description]: command [...] returned` is no link.", "",
        "`roslaunch foo_pkg run.launch x:=1` `rosrun foo_pkg talker --arg` `rostest foo_pkg it.test`",
        "`make` `make demo GUI=1` `CHEFBOT_X=1 make test` `make -C sub sketch` `make -Csub all`",
        "`keyboard_teleop: Run it in a terminal, e.g. 'roslaunch foo_pkg run.launch' (output=\"screen\")`",
        "`rosrun tf tf_echo map base_link` `roslaunch chefbot_gazebo world.launch` `rosrun PKG NODE`",
        "`roslaunch foo_pkg <your.launch>` `rosrun $(PKG) x` `roslaunch foo/launch/run.launch`", "",
        "```bash",
        "source env.sh && roslaunch foo_pkg \\",
        "    run.launch ns:=r1   # make nothing-here",
        "bash tools/with_env.sh rosrun foo_pkg talker",
        "python tools/run_tests.py --only rostest -k test/faults_",
        "```", "",
        "```python",
        "subprocess.run('make nothing', shell=True)",
        "```",
    ])
    assert _check(tree, text) == []


def test_checker_names_every_broken_reference(tree: Workspace) -> None:
    text = "\n".join([
        "# T",
        "[gone](gone.md) ![img](../missing.png)",
        "<img src=\"nope.png\"> [anchor](a.md#no-such-heading) [self](#nope)",
        "`roslaunch foo_pkg missing.launch` `rosrun foo_pkg not_executable` `rosrun foo_pkg absent`",
        "`make bench` `make -C sub flash` `roslaunch chefbot_typo x.launch` `rostest foo_pkg none.test`",
        "```",
        "make demo && make lint",
        "```",
    ])
    problems = _check(tree, text)
    expected = [
        "docs/t.md:2: broken link 'gone.md' (no file docs/gone.md)",
        "docs/t.md:2: broken link '../missing.png' (no file missing.png)",
        "docs/t.md:3: broken link 'a.md#no-such-heading' (no heading '#no-such-heading' in docs/a.md)",
        "docs/t.md:3: broken link '#nope' (no heading '#nope' in docs/t.md)",
        "docs/t.md:3: broken link 'nope.png' (no file docs/nope.png)",
        "docs/t.md:4: 'roslaunch foo_pkg missing.launch': no file missing.launch in package foo_pkg (foo)",
        "docs/t.md:4: 'rosrun foo_pkg not_executable': no executable not_executable in package foo_pkg (foo)",
        "docs/t.md:4: 'rosrun foo_pkg absent': no executable absent in package foo_pkg (foo)",
        "docs/t.md:5: 'make bench': no target bench in Makefile",
        "docs/t.md:5: 'make -C sub flash': no target flash in sub/Makefile",
        "docs/t.md:5: 'roslaunch chefbot_typo x.launch': no package chefbot_typo in this workspace",
        "docs/t.md:5: 'rostest foo_pkg none.test': no file none.test in package foo_pkg (foo)",
        "docs/t.md:7: 'make lint': no target lint in Makefile",
    ]
    assert problems == expected


def test_slug_follows_github() -> None:
    assert slug("A namespaced robot (`ns:=chefbot1`)") == "a-namespaced-robot-nschefbot1"
    assert slug("Robot monitor: the book's rqt tools") == "robot-monitor-the-books-rqt-tools"
    assert slug("`make demo` settings") == "make-demo-settings"
    assert slug("Tables on the SLAM map") == "tables-on-the-slam-map"

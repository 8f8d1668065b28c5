#!/usr/bin/env python3
"""Generate every node's Parameters table in its package README from the code's own config.

    bash tools/with_env.sh python tools/gen_node_docs.py           # write the tables
    bash tools/with_env.sh python tools/gen_node_docs.py --check   # exit 1 on any disagreement

What a node reads: each node script ``<pkg>/nodes/<node>`` declares module-level
``chefbot_common.params.ParamSpec`` objects (a config dataclass and the parameter name(s) of its
fields) and lists them in ``PARAMS``; its ``main()`` reads through those same objects, so the
table is what the node reads.  The script is imported under another name than ``__main__``
(nothing starts); nodes without ROS parameters (command-line tools) declare ``PARAMS = ()``.

Columns, per field of each spec (dataclass field order):

* Parameter: the name as the user sets it (``~rate`` private, ``ticks_meter`` relative to the
  node's namespace); names tried in order read "`~a` (falls back to `a`)".
* Type: of the code default (bool, int, float, str, list, dict), or the field's annotation when
  it is a union (``int | str``; ``None`` left out).
* Default: the value the package's shipped ``param/*.yaml`` gives the node where a launch file of
  the workspace loads one for it (a ``<rosparam file=...>`` inside the ``<node>``: private keys; at
  the node's group level: relative keys and the section named after the node), else the code
  default.  When they differ the yaml value is shown and the meaning ends "code default X".
  Only yaml files of the node's own package count; ``<param>`` overrides in launch files do not.
* Unit and Meaning, one rule: the comment on the dataclass field (with its continuation comment
  lines in the same column) comes first.  It may start with the unit, either ``[unit]`` or a
  known unit word (``s``, ``m``, ``Hz``, ``m/s``, ``rad``, ``ticks`` ... see ``UNITS``, or
  ``X per Y``), optionally followed by ``:``/``,``; or end with it in parentheses (``... of wheel
  travel (ticks/m)``); the rest is the meaning.  What the field comment lacks (unit, or meaning)
  comes from the yaml key's trailing comment (``# [m] ...``, same form), and a meaning still
  missing from the class docstring's "``name``: meaning; ..." entry.

The table goes between ``<!-- BEGIN generated params <pkg>/<node> -->`` and
``<!-- END generated params -->`` in ``<pkg>/README.md``.  Write mode only replaces what lies
between existing markers; a node without markers (or markers naming no node) is reported, not
invented.  ``--check`` writes nothing and exits 1 listing every stale table (with a diff), every
node without markers and every marker pair that names no node.
"""
from __future__ import annotations

import argparse
import dataclasses
import difflib
import importlib.machinery
import importlib.util
import inspect
import io
import linecache
import re
import signal
import sys
import tokenize
import xml.etree.ElementTree as ET
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from types import ModuleType
from typing import Any

import yaml

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = tuple(sorted(d.parent.name for d in ROOT.glob("*/nodes") if d.is_dir()))   # packages with nodes
BEGIN_RE = re.compile(r"^<!-- BEGIN generated params (\S+?)/(\S+) -->\s*$")
END = "<!-- END generated params -->"
HEADER = "| Parameter | Type | Default | Unit | Meaning |\n|---|---|---|---|---|"
UNITS = {"s", "ms", "m", "cm", "mm", "m/s", "m/s^2", "rad", "rad/s", "rad/s^2", "deg", "Hz", "V", "A", "px",
         "cells", "ticks", "ticks/m", "fraction", "%", "m^2", "rad^2", "readings", "lines", "scans", "bytes",
         "cmd", "cmd/(m/s)", "cmd/m", "cmd/(m/s^2)", "particles", "baud", "m²", "rad²", "1/m", "1/s", "Ah",
         "rad/s/sqrt(s)"}
LONG_DEFAULT = 60   # characters: a longer list/dict default is summarised, the yaml file has it
MISSING = object()


# ---------------------------------------------------------------- the node's declared specs
def load_node(path: Path) -> ModuleType:
    """Import a node script as module ``_chefbot_node_<pkg>_<node>`` (its main() does not run)."""
    name = f"_chefbot_node_{path.parent.parent.name}_{path.name}"
    linecache.checkcache()   # inspect.getsource must see the file as it is now
    loader = importlib.machinery.SourceFileLoader(name, str(path))
    module = importlib.util.module_from_spec(importlib.util.spec_from_loader(name, loader))
    sys.modules[name] = module   # dataclasses look their module up while the script runs
    sigint = signal.getsignal(signal.SIGINT)   # chefbot_common.quiet_interrupt replaces it on import
    try:
        loader.exec_module(module)
    finally:
        signal.signal(signal.SIGINT, sigint)
    return module


def node_specs(path: Path) -> tuple:
    """The node's ``PARAMS`` (ParamSpec objects); ValueError when it declares none."""
    from chefbot_common.params import ParamSpec

    specs = getattr(load_node(path), "PARAMS", None)
    if not isinstance(specs, tuple) or not all(isinstance(s, ParamSpec) for s in specs):
        raise ValueError(f"{path.relative_to(ROOT)}: no module-level PARAMS tuple of ParamSpec objects")
    return specs


def field_comments(cls: type) -> dict[str, str]:
    """Field -> its trailing comment (plus continuation comment lines in the same column)."""
    out: dict[str, str] = {}
    for klass in reversed([k for k in cls.__mro__ if dataclasses.is_dataclass(k)]):
        try:
            src = inspect.getsource(klass)
        except (OSError, TypeError):
            continue
        lines = src.splitlines()
        comments = {}      # row (0-based) -> (col of "#", col of its text, text, code before it)
        for tok in tokenize.generate_tokens(io.StringIO(src).readline):
            if tok.type == tokenize.COMMENT:
                row, col = tok.start[0] - 1, tok.start[1]
                text = tok.string.lstrip("#").strip()
                text_col = col + len(tok.string) - len(tok.string.lstrip("#").lstrip())
                comments[row] = (col, text_col, text, bool(lines[row][:col].strip()))
        start = next((i for i, ln in enumerate(lines) if ln.lstrip().startswith("class ")), 0)
        body = [i for i, ln in enumerate(lines) if ln.strip() and i > start]
        indent = min((len(lines[i]) - len(lines[i].lstrip()) for i in body), default=4)
        for i, ln in enumerate(lines):
            m = re.match(rf"^ {{{indent}}}(\w+)\s*:", ln)
            if not m or i not in comments or not comments[i][3]:
                continue
            col, text_col, text, _ = comments[i]
            parts, j = [text], i + 1
            # continuation: a comment-only line with its "#" or its text in the column of the field's comment
            while j in comments and not comments[j][3] and (abs(comments[j][0] - col) <= 2
                                                              or abs(comments[j][1] - text_col) <= 2):
                parts.append(comments[j][2])
                j += 1
            out[m.group(1)] = " ".join(p for p in parts if p)
    return out


def docstring_entries(cls: type) -> dict[str, str]:
    """Field -> its entry in the class docstring's "``field``: meaning; ..." list, if it has one."""
    doc = " ".join((inspect.getdoc(cls) or "").split())
    out = {}
    for m in re.finditer(r"``(\w+)``(?:/``\w+``)*\s*:\s*(.+?)(?=;\s|\.\s|\.$|$)", doc):
        out.setdefault(m.group(1), m.group(2).strip())
    return out


def split_unit(text: str) -> tuple[str, str]:
    """(unit, meaning) of a comment: ``[unit] meaning``, ``unit: meaning`` or ``unit meaning``."""
    text = text.strip()
    m = re.match(r"^\[([^\[\],]+)\]\s*[:,]?\s*(.*)$", text)
    if m:
        return m.group(1).strip(), m.group(2).strip()
    m = re.match(r"^(\S+?) per (\S+?)([:,;]|\s|$)\s*(.*)$", text)
    if m and m.group(1) in UNITS:
        return f"{m.group(1)} per {m.group(2)}", m.group(4).strip()
    m = re.match(r"^([^\s:,;]+)(?:\s*[:,;]\s*|\s+|$)(.*)$", text)
    if m and m.group(1) in UNITS:
        return m.group(1), m.group(2).strip()
    m = re.match(r"^(.*\S)\s+\(((?:\([^()\s]+\)|[^()\s])+)\)$", text)   # "meaning (unit)"
    unitlike = m and (m.group(2) in UNITS or re.fullmatch(r"[A-Za-z(][^\d\s]*[/^].*", m.group(2)))
    if unitlike and not m.group(1).endswith(" per"):
        return m.group(2), m.group(1)
    return "", text


# ---------------------------------------------------------------- launch files and yaml
@dataclass
class YamlSource:
    """A yaml file a launch file loads for one node: ``private`` (inside its <node>) or at its namespace."""

    path: Path
    private: bool
    node_name: str
    data: Any = None
    comments: dict[tuple[str, ...], str] = field(default_factory=dict)


def _launch_files() -> list[Path]:
    files: list[Path] = []
    for pkg_dir in sorted(p for p in ROOT.iterdir() if (p / "package.xml").exists()):
        for pattern in ("*.launch", "*.launch.xml"):
            files += sorted((pkg_dir / "launch").rglob(pattern))
    return files


def _parse(path: Path) -> ET.Element | None:
    try:
        return ET.parse(path).getroot()
    except (ET.ParseError, OSError):
        return None


def _substitute(text: str, path: Path, depth: int = 0) -> list[str]:
    """Launch substitutions: $(find pkg) -> the package directory; $(arg a) -> its default in
    ``path``, or the values includers of ``path`` pass.  Candidates that could not be resolved are left out."""
    if depth > 6:
        return []
    text = re.sub(r"\$\(find (\w+)\)", lambda m: str(ROOT / m.group(1)), text)
    m = re.search(r"\$\(arg (\w+)\)", text)
    if not m:
        return [] if "$(" in text else [text]
    values: list[str] = []
    root = _parse(path)
    arg = next((a for a in root.iter("arg") if a.get("name") == m.group(1)), None) if root is not None else None
    if arg is not None and (arg.get("value") or arg.get("default")) is not None:
        values.append(arg.get("value") if arg.get("value") is not None else arg.get("default"))
        where = [path]
    else:   # no default here: what the files including this one pass
        where = []
        for inc_path in _launch_files():
            inc_root = _parse(inc_path)
            for inc in inc_root.iter("include") if inc_root is not None else ():
                if any(Path(f).resolve() == path.resolve() for f in _substitute(inc.get("file", ""), inc_path,
                                                                               depth + 1)):
                    for a in inc.iter("arg"):
                        if a.get("name") == m.group(1) and a.get("value") is not None:
                            values.append(a.get("value"))
                            where.append(inc_path)
    out: list[str] = []
    for v, w in zip(values, where, strict=False):
        for resolved in _substitute(v, w, depth + 1):
            out += _substitute(text[:m.start()] + resolved + text[m.end():], path, depth + 1)
    return out


def _yaml_comments(path: Path) -> dict[tuple[str, ...], str]:
    """Key path -> trailing comment (with continuation comment lines indented deeper)."""
    out: dict[tuple[str, ...], str] = {}
    stack: list[tuple[int, str]] = []
    last: tuple[tuple[str, ...], int] | None = None
    for line in path.read_text(encoding="utf-8").splitlines():
        stripped = line.strip()
        indent = len(line) - len(line.lstrip())
        if stripped.startswith("#"):
            if last is not None and indent > last[1] and last[0] in out:
                out[last[0]] += " " + stripped.lstrip("#").strip()
            else:
                last = None
            continue
        m = re.match(r"^(\s*)([\w/~.-]+)\s*:(.*)$", line)
        if not m:
            last = None
            continue
        while stack and stack[-1][0] >= indent:
            stack.pop()
        stack.append((indent, m.group(2)))
        key = tuple(k for _, k in stack)
        rest = m.group(3)
        hash_at = rest.find(" #") if not rest.lstrip().startswith("#") else rest.find("#")
        if hash_at >= 0:
            out[key] = rest[hash_at:].strip().lstrip("#").strip()
        last = (key, indent)
    return out


def yaml_sources(pkg: str, node: str) -> list[YamlSource]:
    """The node's own package's param/*.yaml files the workspace's launch files load for it."""
    param_dir = (ROOT / pkg / "param").resolve()
    sources: list[YamlSource] = []
    for launch in _launch_files():
        root = _parse(launch)
        if root is None:
            continue
        parents = {child: parent for parent in root.iter() for child in parent}
        for el in root.iter("node"):
            if el.get("pkg") != pkg or el.get("type") != node:
                continue
            name = el.get("name", node)
            found = [(r, True) for r in el.findall("rosparam")]
            up = parents.get(el)
            while up is not None:
                found += [(r, False) for r in up.findall("rosparam")]
                up = parents.get(up)
            for rp, private in found:
                if rp.get("command", "load") != "load" or rp.get("ns") or not rp.get("file"):
                    continue
                for f in _substitute(rp.get("file"), launch):
                    p = Path(f).resolve()
                    if p.parent == param_dir and p.exists() and not any(
                            s.path == p and s.private == private and s.node_name == name for s in sources):
                        sources.append(YamlSource(p, private, name, yaml.safe_load(p.read_text(encoding="utf-8")),
                                                  _yaml_comments(p)))
    return sources


def _yaml_key(src: YamlSource, pname: str) -> tuple[str, ...] | None:
    """Key path of parameter ``pname`` in a yaml source, None if the source cannot set it."""
    if pname.startswith("/"):
        return None
    if pname.startswith("~"):
        keys = tuple(pname[1:].split("/"))
        return keys if src.private else (src.node_name, *keys)
    return None if src.private else tuple(pname.split("/"))


def _lookup(data: Any, keys: tuple[str, ...]) -> Any:
    for k in keys:
        if not isinstance(data, dict) or k not in data:
            return MISSING
        data = data[k]
    return data


# ---------------------------------------------------------------- rows and tables
@dataclass(frozen=True)
class Row:
    name: str
    type: str
    default: str
    unit: str
    meaning: str


def _type_name(f: dataclasses.Field, default: Any) -> str:
    annotation = str(f.type)
    if "|" in annotation:
        return " or ".join(p.strip() for p in annotation.split("|") if p.strip() != "None")
    for t in (bool, int, float, str, list, dict, tuple):
        if isinstance(default, t):
            return "list" if t is tuple else t.__name__
    return annotation


def format_value(v: Any) -> str:
    """A value as the user writes it in yaml, in backticks (paths inside the workspace as ``$(find pkg)``)."""
    if v is None:
        return "unset"
    if isinstance(v, bool):
        text = "true" if v else "false"
    elif isinstance(v, str):
        for pkg_dir in ROOT.iterdir():
            if v.startswith(str(pkg_dir) + "/") and (pkg_dir / "package.xml").exists():
                v = f"$(find {pkg_dir.name}){v[len(str(pkg_dir)):]}"
                break
        text = v if v else '""'
    elif isinstance(v, (list, tuple, dict)):
        text = yaml.safe_dump(list(v) if isinstance(v, tuple) else v, default_flow_style=True, width=1000).strip()
        if len(text) > LONG_DEFAULT:
            return f"{len(v)} {'entries' if isinstance(v, dict) else 'items'}"
    else:
        text = repr(v)
    return f"`{text}`"


def _as_type(v: Any, default: Any) -> Any:
    """A yaml value as the node takes it (an int given for a float field is a float)."""
    if isinstance(default, float) and isinstance(v, int) and not isinstance(v, bool):
        return float(v)
    return v


def spec_rows(spec: Any, sources: list[YamlSource]) -> list[Row]:
    comments = field_comments(spec.cls)
    rows = []
    for f in dataclasses.fields(spec.cls):
        if f.name not in spec.names:
            continue
        names = spec.names[f.name]
        names = (names,) if isinstance(names, str) else tuple(names)
        shown = f"`{names[0]}`"
        if len(names) > 1:
            shown += " (falls back to " + ", then ".join(f"`{n}`" for n in names[1:]) + ")"
        default = f.default if f.default is not dataclasses.MISSING else (
            f.default_factory() if f.default_factory is not dataclasses.MISSING else None)
        yaml_value, yaml_comment = MISSING, ""
        for src in sources:
            for n in names:
                key = _yaml_key(src, n)
                if key is None:
                    continue
                v = _lookup(src.data, key)
                if v is not MISSING:
                    yaml_value, yaml_comment = v, src.comments.get(key, "")
                    break
            if yaml_value is not MISSING:
                break
        comment = comments.get(f.name, "")
        for n in names:   # "~Kp, command units per (m/s)": the name again is no meaning
            comment = re.sub(rf"^~?{re.escape(n.lstrip('~'))}\s*,\s*", "", comment)
        unit, meaning = split_unit(comment)
        y_unit, y_meaning = split_unit(yaml_comment)
        unit, meaning = unit or y_unit, meaning or y_meaning
        if not meaning:
            d_unit, meaning = split_unit(docstring_entries(spec.cls).get(f.name, ""))
            unit = unit or d_unit
        shown_default = default
        if yaml_value is not MISSING:
            yaml_value = _as_type(yaml_value, default)
            if yaml_value != default or type(yaml_value) is not type(default):
                shown_default = yaml_value
                meaning = (meaning.rstrip(". ") + "; " if meaning else "") + f"code default {format_value(default)}"
        if shown_default is not default and format_value(shown_default).endswith(("items", "entries")):
            meaning += f" (see `param/{src.path.name}`)"
        rows.append(Row(shown, _type_name(f, default), format_value(shown_default), unit, meaning))
    return rows


def _cell(text: str) -> str:
    """Table-safe: pipes escaped, ``<name>`` not taken for an HTML tag."""
    text = re.sub(r"<(/?[A-Za-z_][^<>]*)>", r"&lt;\1&gt;", text)
    return text.replace("|", "\\|").replace("\n", " ") or " "


def render(rows: list[Row]) -> str:
    """The marker region's content: a table, or "None." for a node without ROS parameters."""
    if not rows:
        return "None."
    body = [f"| {r.name} | {r.type} | {_cell(r.default)} | {_cell(r.unit)} | {_cell(r.meaning)} |" for r in rows]
    return "\n".join([HEADER, *body])


def node_table(pkg: str, node: str) -> str:
    sources = yaml_sources(pkg, node)
    rows: dict[str, Row] = {}
    for spec in node_specs(ROOT / pkg / "nodes" / node):
        for row in spec_rows(spec, sources):
            if row.name in rows:   # two fields read from one parameter: one row
                first = rows[row.name]
                rows[row.name] = dataclasses.replace(first, meaning=f"{first.meaning}; also {row.meaning}".strip("; "))
            else:
                rows[row.name] = row
    return render(list(rows.values()))


# ---------------------------------------------------------------- READMEs
def all_nodes(packages: Iterable[str] = PACKAGES) -> list[tuple[str, str]]:
    """(package, node) of every script in <pkg>/nodes/."""
    return [(pkg, p.name) for pkg in packages for p in sorted((ROOT / pkg / "nodes").glob("*")) if p.is_file()]


def regions(text: str) -> dict[tuple[str, str], tuple[int, int]]:
    """(pkg, node) -> (line index of BEGIN, line index of END) in a README's lines."""
    lines = text.split("\n")
    out, open_at = {}, None
    for i, line in enumerate(lines):
        m = BEGIN_RE.match(line)
        if m:
            open_at = ((m.group(1), m.group(2)), i)
        elif line.strip() == END and open_at is not None:
            out[open_at[0]] = (open_at[1], i)
            open_at = None
    return out


def run(check: bool, packages: Iterable[str] = PACKAGES, out=sys.stdout) -> list[str]:
    """Check or write every table; returns the problems (also printed to ``out``)."""
    problems: list[str] = []
    nodes = all_nodes(packages)
    for pkg in packages:
        readme = ROOT / pkg / "README.md"
        text = readme.read_text(encoding="utf-8") if readme.exists() else ""
        lines = text.split("\n")
        found = regions(text)
        for (mpkg, mnode) in found:
            if (mpkg, mnode) not in nodes or mpkg != pkg:
                problems.append(f"{pkg}/README.md: markers for {mpkg}/{mnode}, which is no node of {pkg}/nodes/")
        for npkg, node in (n for n in nodes if n[0] == pkg):
            if (npkg, node) not in found:
                problems.append(f"{pkg}/README.md: no '<!-- BEGIN generated params {pkg}/{node} -->' markers "
                                f"for node {node}")
        for (npkg, node), (b, e) in sorted(found.items(), key=lambda kv: -kv[1][0]):
            if (npkg, node) not in nodes or npkg != pkg:
                continue
            try:
                want = node_table(pkg, node).split("\n")
            except (ValueError, ImportError) as exc:
                problems.append(f"{pkg}/nodes/{node}: {exc}")
                continue
            have = lines[b + 1:e]
            if have != want:
                if check:
                    diff = "\n".join(difflib.unified_diff(have, want, "README", "generated", lineterm="", n=0))
                    problems.append(f"{pkg}/README.md: the parameter table of {node} is stale "
                                    f"(run tools/gen_node_docs.py):\n{diff}")
                else:
                    lines[b + 1:e] = want
        new = "\n".join(lines)
        if not check and new != text:
            readme.write_text(new, encoding="utf-8")
            print(f"wrote {readme.relative_to(ROOT)}", file=out)
    for p in problems:
        print(p, file=out)
    return problems


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--check", action="store_true", help="write nothing; exit 1 on any disagreement")
    ap.add_argument("--show", metavar="PKG/NODE", help="print one node's table and exit")
    a = ap.parse_args(argv)
    if a.show:
        pkg, node = a.show.split("/", 1)
        print(node_table(pkg, node))
        return 0
    return 1 if run(a.check) else 0


if __name__ == "__main__":
    sys.exit(main())

#!/usr/bin/env python3
"""Write the ``--hash`` lines of requirements.txt from PyPI's simple index.

    python tools/pin_hashes.py            # rewrite requirements.txt in place
    python tools/pin_hashes.py --check    # exit 1 if a pin lacks its hashes

Every ``name==version`` pin gets the sha256 of each file pip could pick for it on
CPython 3.11 Linux x86_64 (any manylinux level; pure-Python wheels) plus the
sdist, as PyPI publishes them (the ``#sha256=`` of each link).  ``setup.sh``
installs with ``pip --require-hashes``, so a changed or substituted file fails
the install.  Run this after changing a pin.  Comments are kept (an inline comment
moves to its own line above the pin: pip's line continuation cannot carry one).
"""
from __future__ import annotations

import argparse
import re
import sys
import urllib.request
from html.parser import HTMLParser
from pathlib import Path

from packaging.tags import Tag
from packaging.utils import canonicalize_name, parse_sdist_filename, parse_wheel_filename
from packaging.version import Version

REQS = Path(__file__).resolve().parents[1] / "requirements.txt"
INDEX = "https://pypi.org/simple"
PIN = re.compile(r"^([A-Za-z0-9_.\-]+)==([^\s#\\]+)\s*(?:#\s*(.*))?$")


def _wanted(tag: Tag) -> bool:
    """Could pip on CPython 3.11 / Linux x86_64 (glibc) install a wheel with this tag?"""
    py_ok = tag.interpreter in ("cp311", "py3", "py311") or (tag.interpreter.startswith("cp3") and tag.abi == "abi3"
                                                           and int(tag.interpreter[3:]) <= 11)
    abi_ok = tag.abi in ("cp311", "abi3", "none")
    plat_ok = tag.platform == "any" or (tag.platform.endswith("_x86_64") and "manylinux" in tag.platform)
    return py_ok and abi_ok and plat_ok


class _Links(HTMLParser):
    def __init__(self) -> None:
        super().__init__()
        self.links: list[tuple[str, str]] = []  # (filename, sha256)

    def handle_starttag(self, tag: str, attrs: list) -> None:
        href = dict(attrs).get("href") or ""
        if tag == "a" and "#sha256=" in href:
            url, digest = href.split("#sha256=", 1)
            self.links.append((url.rsplit("/", 1)[-1], digest))


def hashes(name: str, version: str) -> list[str]:
    """sha256 of every file of ``name==version`` pip could choose here (sorted)."""
    url = f"{INDEX}/{canonicalize_name(name)}/"
    with urllib.request.urlopen(url, timeout=60) as r:
        parser = _Links()
        parser.feed(r.read().decode())
    want, out = Version(version), set()
    for fn, digest in parser.links:
        try:
            if fn.endswith(".whl"):
                _n, v, _b, tags = parse_wheel_filename(fn)
                ok = v == want and any(_wanted(t) for t in tags)
            else:
                _n, v = parse_sdist_filename(fn)
                ok = v == want
        except ValueError:
            continue
        if ok:
            out.add(digest)
    if not out:
        raise SystemExit(f"pin_hashes: no file of {name}=={version} on {url}")
    return sorted(out)


def render(lines: list[str], lookup=hashes) -> list[str]:
    out: list[str] = []
    for line in lines:
        s = line.strip()
        if s.startswith("--hash="):
            continue  # regenerated below
        m = PIN.match(s.rstrip("\\").strip())
        if not m:
            out.append(line.rstrip("\n"))
            continue
        name, version, comment = m.groups()
        if comment:
            out.append(f"# {name}: {comment}")
        hs = lookup(name, version)
        out.append(f"{name}=={version} \\")
        out.extend(f"    --hash=sha256:{h}" + (" \\" if i < len(hs) - 1 else "") for i, h in enumerate(hs))
    return out


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--check", action="store_true", help="only check that every pin has hashes")
    args = ap.parse_args(argv)
    lines = REQS.read_text(encoding="utf-8").splitlines()
    if args.check:
        text = "\n".join(lines)
        bare = [ln for ln in lines if PIN.match(ln.strip().rstrip("\\").strip())
                and not ln.rstrip().endswith("\\")]
        if bare or "--hash=sha256:" not in text:
            print(f"pin_hashes: pins without hashes: {bare}", file=sys.stderr)
            return 1
        return 0
    REQS.write_text("\n".join(render(lines)) + "\n", encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

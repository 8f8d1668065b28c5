"""The workspace itself: every package is a valid catkin package, found by ROS, importable.

These are also the placeholder tests of packages that hold no code yet.
"""
from __future__ import annotations

import ast
import importlib
import re
import subprocess
from pathlib import Path
from xml.etree import ElementTree

import pytest
from catkin_pkg.package import parse_package

ROOT = Path(__file__).resolve().parents[2]
PACKAGES = {
    "chefbot_common": "chefbot_common",
    "chefbot_msgs": "chefbot_msgs",
    "chefbot_description": "chefbot_description",
    "chefbot_bringup": "chefbot_bringup",
    "chefbot_navigation": "chefbot_navigation",
    "chefbot_sim": "chefbot_sim",
    "chefbot_gui": "chefbot_gui",
    "chefbot_vision": "chefbot_vision",
    "chefbot_fleet": "chefbot_fleet",
    "tests": "chefbot_tests",
}


def test_top_level_layout() -> None:
    for name in [*PACKAGES, "firmware", "README.md", "Makefile", ".ci/run", "requirements.txt"]:
        assert (ROOT / name).exists(), f"missing top-level {name}"


@pytest.mark.parametrize("directory,name", sorted(PACKAGES.items()))
def test_package_manifest(directory: str, name: str) -> None:
    pkg = parse_package(str(ROOT / directory / "package.xml"))
    assert pkg.name == name
    assert pkg.package_format == 2
    assert pkg.licenses == ["MIT"]
    assert pkg.description.strip()
    assert (ROOT / directory / "README.md").is_file(), f"{directory} has no README.md"
    # catkin_make must have configured the package (it is in the devel space's package index)
    out = subprocess.run(["rospack", "find", name], capture_output=True, text=True, check=False)
    assert out.returncode == 0, out.stderr
    assert Path(out.stdout.strip()) == ROOT / directory


@pytest.mark.parametrize("module", [m for m in PACKAGES.values() if m != "chefbot_tests"])
def test_python_module_importable_without_rospy(module: str, tmp_path: Path) -> None:
    """Pure modules must import without pulling in rospy (STYLE.md, 'Core / node split')."""
    code = (f"import sys, {module}, pkgutil, importlib\n"
            f"for m in pkgutil.walk_packages({module}.__path__, '{module}.'):\n"
            f"    if m.name.split('.')[-1] in ('ros_io',) or '.ros' in m.name:\n"
            f"        continue\n"
            f"    importlib.import_module(m.name)\n"
            f"bad = [n for n in sys.modules if n == 'rospy' or n.startswith('rospy.')]\n"
            f"assert not bad, 'pure modules imported rospy'\n")
    # cwd outside the repo: from the top level, 'import chefbot_gui' would find the package
    # directory itself as a namespace package instead of the devel-space module.
    out = subprocess.run(["python", "-c", code], capture_output=True, text=True, check=False, cwd=tmp_path)
    assert out.returncode == 0, out.stderr


def public_defs_without_docstring(path: Path) -> list[str]:
    """Public classes, functions and methods (nested in classes) of ``path`` with no docstring."""
    missing = []

    def walk(body: list[ast.stmt], prefix: str) -> None:
        for node in body:
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)) and \
                    not node.name.startswith("_"):
                if ast.get_docstring(node) is None:
                    missing.append(f"{path.relative_to(ROOT)}:{node.lineno} {prefix}{node.name}")
                if isinstance(node, ast.ClassDef):
                    walk(node.body, f"{prefix}{node.name}.")

    walk(ast.parse(path.read_text(), str(path)).body, "")
    return missing


def test_pure_cores_have_docstrings() -> None:
    """Every public function and class of the pure core modules (src/<pkg>/, not ros_*) says what it is for."""
    files = [f for f in sorted(ROOT.glob("*/src/*/**/*.py")) if not f.name.startswith("ros")]
    assert len(files) > 50, "the source files were not found"
    missing = [m for f in files for m in public_defs_without_docstring(f)]
    assert not missing, "no docstring:\n" + "\n".join(missing)


def test_requirements_are_pinned_with_hashes() -> None:
    text = (ROOT / "requirements.txt").read_text().replace("\\\n", " ")  # join pip's continuations
    reqs = [ln.split("#")[0].split() for ln in text.splitlines() if ln.split("#")[0].strip()]
    assert reqs
    for pin, *opts in reqs:
        assert "==" in pin, f"requirement not pinned exactly: {pin}"
        assert opts and all(re.fullmatch(r"--hash=sha256:[0-9a-f]{64}", o) for o in opts), \
            f"{pin}: needs --hash=sha256:... (python tools/pin_hashes.py)"
    assert "--require-hashes" in (ROOT / "tools" / "setup.sh").read_text()


def test_venv_python_sees_rospy_and_pypi() -> None:
    for mod in ("rospy", "roslaunch", "actionlib", "tf2_ros", "numpy", "pybullet", "PyQt5", "serial", "xacro"):
        importlib.import_module(mod)


def test_no_merge_conflict_markers() -> None:
    """No tracked file keeps a merge's conflict markers (a CMakeLists.txt with them breaks a fresh
    build while an incremental one, with CMake's cache, still passes)."""
    out = subprocess.run(["git", "grep", "-n", "-E", r"^(<<<<<<< |>>>>>>> )"], cwd=ROOT, capture_output=True,
                         text=True, check=False)
    if out.returncode not in (0, 1):
        pytest.skip(f"not a git checkout: {out.stderr.strip()}")
    assert out.stdout == "", f"conflict markers:\n{out.stdout}"


def test_launch_and_test_files_are_well_formed_xml() -> None:
    """roslaunch reads a launch or .test file only when it is run, so a file that is no well-formed XML
    (``--`` inside a comment) failed only at the end of a 23-minute CI run (2026-11-24)."""
    out = subprocess.run(["git", "ls-files", "*.launch", "*.launch.xml", "*.test"], cwd=ROOT, capture_output=True,
                         text=True, check=False)
    if out.returncode != 0:
        pytest.skip(f"not a git checkout: {out.stderr.strip()}")
    files = out.stdout.split()
    assert len(files) > 20, files
    bad = []
    for name in files:
        try:
            ElementTree.parse(ROOT / name)
        except ElementTree.ParseError as exc:
            bad.append(f"{name}: {exc}")
    assert not bad, "\n".join(bad)


def _rospy_nodes() -> list[Path]:
    """The node executables (python scripts under */nodes) that call rospy.init_node with rospy's
    signal handlers (not the Qt GUIs, which disable them, nor the tools that are no nodes)."""
    return sorted(p for p in ROOT.glob("chefbot_*/nodes/*")
                  if p.is_file() and p.read_bytes().startswith(b"#!/usr/bin/env python3")
                  and "rospy.init_node(" in (src := p.read_text()) and "disable_signals=True" not in src)


@pytest.mark.parametrize("script", _rospy_nodes(), ids=lambda p: f"{p.parent.parent.name}/{p.name}")
def test_nodes_stop_quietly_while_starting(script: Path) -> None:
    """A rospy node that keeps rospy's signal handling imports chefbot_common.quiet_interrupt before
    anything else and ends with ``quiet_interrupt.run(main)``: stopped by roslaunch anywhere in its
    startup it exits by itself without a traceback (tests/test/node_stop.test shows why)."""
    tree = ast.parse(script.read_text())
    imports = [n for n in tree.body if isinstance(n, ast.Import)
               or isinstance(n, ast.ImportFrom) and n.module != "__future__"]
    first = imports[0]
    assert isinstance(first, ast.ImportFrom) and first.module == "chefbot_common" \
        and [a.name for a in first.names] == ["quiet_interrupt"], \
        f"{script.name}: the first import is not 'from chefbot_common import quiet_interrupt'"
    last = tree.body[-1]
    assert isinstance(last, ast.If) and ast.unparse(last.body[-1]) == "quiet_interrupt.run(main)", \
        f"{script.name}: does not end with 'if __name__ == \"__main__\": quiet_interrupt.run(main)'"

"""Every node's Parameters table in its package README is what the node reads (tools/gen_node_docs.py).

* ``test_readme_tables_are_current``: the generator's ``--check`` over the real tree; fails with the
  diff when a table is stale, a node has no markers, or markers name no node.
* ``test_every_table_row_has_a_meaning``: no row of the real tree has an empty Meaning (or only the
  generator's "code default X" note); fails naming node and parameter.
* The generator on a small fake package: a new field, a changed default, a missing README marker
  and markers for no node are all reported; yaml defaults win and name the code default.
* That the documented list IS what the node reads holds by construction: a node reads parameters
  only through the ``ParamSpec`` objects listed in its ``PARAMS`` (``SPEC.read(rospy.get_param)``,
  or a helper that reads through them), and the generator documents those same objects.  The
  tests below pin the construction: no node or package module calls ``get_param``/``read_config``
  itself, every ``ParamSpec`` a node can see is in its ``PARAMS``, every ``PARAMS`` entry is read
  by the node, and the shared readers ask exactly their specs' names (a recording ``get``).
"""
from __future__ import annotations

import ast
import importlib.util
import io
import re
import sys
import textwrap
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


sys.path.insert(0, str(ROOT / "tools"))
import gen_node_docs as gen  # noqa: E402  (tools/ is no package)


# ---------------------------------------------------------------- the real tree
def test_readme_tables_are_current() -> None:
    out = io.StringIO()
    problems = gen.run(check=True, out=out)
    assert not problems, ("README parameter tables disagree with the nodes; run "
                          "`bash tools/with_env.sh python tools/gen_node_docs.py`:\n" + out.getvalue())


# what the generator appends when the shipped yaml overrides the code default: no meaning by itself
_CODE_DEFAULT_NOTE = re.compile(r"(?:^|;\s*)code default `[^`]*`(?: \(see `[^`]*`\))?$")


def test_every_table_row_has_a_meaning() -> None:
    # a field without a trailing comment (nor a yaml comment, nor a class-docstring entry) gives an empty
    # Meaning; "code default X" alone (the yaml overrides a field with a unit-only comment) is no meaning either
    empty = []
    for pkg, node in gen.all_nodes():
        sources = gen.yaml_sources(pkg, node)
        for spec in gen.node_specs(ROOT / pkg / "nodes" / node):
            for row in gen.spec_rows(spec, sources):
                if not _CODE_DEFAULT_NOTE.sub("", row.meaning).strip(" ;"):
                    empty.append(f"{pkg}/{node}: {row.name} ({spec.cls.__name__})")
    assert not empty, ("parameters without a meaning in their README table; add a comment on the dataclass field "
                       "(`name: float = 0.25   # [m] what it does`, see tools/gen_node_docs.py):\n  "
                       + "\n  ".join(empty))


def test_every_node_declares_params() -> None:
    nodes = gen.all_nodes()
    assert len(nodes) >= 26
    for pkg, node in nodes:
        gen.node_specs(ROOT / pkg / "nodes" / node)   # raises naming the node without PARAMS


def _calls(path: Path, names: set[str]) -> list[tuple[int, str]]:
    """(line, name) of every call of a function or method named in ``names`` (passing it is no call)."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Call):
            f = node.func
            name = f.attr if isinstance(f, ast.Attribute) else f.id if isinstance(f, ast.Name) else ""
            if name in names:
                first = node.args[0].value if node.args and isinstance(node.args[0], ast.Constant) else None
                out.append((node.lineno, f"{name}({first!r})"))
    return out


def test_nodes_read_parameters_only_through_their_specs() -> None:
    # slam_offline fills SlamConfig from a slam.yaml FILE (no parameter server, no ROS master)
    file_readers = {("chefbot_navigation", "slam_offline")}
    for pkg, node in gen.all_nodes():
        path = ROOT / pkg / "nodes" / node
        names = {"get_param", "search_param"} | (set() if (pkg, node) in file_readers else {"read_config"})
        assert _calls(path, names) == [], \
            f"{pkg}/nodes/{node} reads parameters itself: declare a ParamSpec in PARAMS and read through it"


def test_package_modules_read_no_stray_parameters() -> None:
    # ros_launchpad asks ROS's own /use_sim_time (is a clock expected?), no setting of the node
    allowed = {("ros_launchpad.py", "get_param('/use_sim_time')")}
    for pkg in gen.PACKAGES + ("chefbot_common",):
        for path in sorted((ROOT / pkg / "src").rglob("*.py")):
            for line, call in _calls(path, {"get_param", "search_param"}):
                assert (path.name, call) in allowed, f"{path.relative_to(ROOT)}:{line}: {call}: read it through a " \
                                                     "ParamSpec the node lists in PARAMS"


# specs read inside a package helper the node calls: (helper name in the node source, where it reads them)
HELPER_READS = {
    "ENCODER_PARAMS": ("read_encoder_range", "chefbot_bringup/src/chefbot_bringup/encoder.py"),
    "URDF": ("load_footprint", "chefbot_navigation/src/chefbot_navigation/ros_move_base.py"),
    "CLOUD": ("CloudInput", "chefbot_navigation/src/chefbot_navigation/ros_cloud.py"),
    "SIM_NODE": ("read_sim_params", "chefbot_sim/src/chefbot_sim/node_params.py"),
    "SIM_OPTIONS": ("read_sim_params", "chefbot_sim/src/chefbot_sim/node_params.py"),
}


def test_every_declared_spec_is_read_and_every_visible_spec_declared() -> None:
    from chefbot_common.params import ParamSpec
    from chefbot_navigation.navigator import MOVE_BASE_PARAMS

    for pkg, node in gen.all_nodes():
        path = ROOT / pkg / "nodes" / node
        module, src = gen.load_node(path), path.read_text(encoding="utf-8")
        declared = module.PARAMS
        for name, value in vars(module).items():
            if isinstance(value, ParamSpec):
                assert any(value is s for s in declared), f"{pkg}/nodes/{node}: {name} is not in PARAMS"
        for spec in declared:
            if any(spec is s for s in MOVE_BASE_PARAMS):
                assert "read_move_base_params(" in src, f"{pkg}/nodes/{node}: MOVE_BASE_PARAMS are not read"
                continue
            names = [n for n, v in vars(module).items() if v is spec]
            names += [k for k in HELPER_READS if f".{k}" in src]   # module attribute (mb.URDF)
            ok = any(f"{n}.read(" in src or f"read_private_config({n}," in src for n in names) or any(
                n in HELPER_READS and HELPER_READS[n][0] + "(" in src
                and f"{n}.read(" in (ROOT / HELPER_READS[n][1]).read_text(encoding="utf-8") for n in names)
            assert ok, f"{pkg}/nodes/{node}: PARAMS lists {names or spec.cls.__name__}, which main() never reads"


def _recorder(values: dict | None = None):
    asked: list[str] = []
    values = values or {}

    def get(name, default):
        asked.append(name)
        return values.get(name, default)
    return get, asked


def _names(*specs) -> set[str]:
    out: set[str] = set()
    for spec in specs:
        for n in spec.names.values():
            out.update((n,) if isinstance(n, str) else n)
    return out


def test_shared_readers_ask_exactly_their_specs() -> None:
    from chefbot_bringup.encoder import ENCODER_PARAMS, read_encoder_range
    from chefbot_navigation.navigator import MOVE_BASE_PARAMS, read_move_base_params
    from chefbot_sim.node_params import SIM_NODE, SIM_OPTIONS, read_sim_params

    get, asked = _recorder()
    read_encoder_range(get)
    assert set(asked) == _names(ENCODER_PARAMS)
    get, asked = _recorder()
    read_move_base_params(get)
    assert set(asked) == _names(*MOVE_BASE_PARAMS)
    get, asked = _recorder({"robot_description": "<robot/>", "~world": "w.yaml"})
    read_sim_params(get)
    assert set(asked) == _names(SIM_NODE, SIM_OPTIONS)


# ---------------------------------------------------------------- the generator on a fake package
NODE = '''\
#!/usr/bin/env python3
"""fake node."""
from dataclasses import dataclass

from chefbot_common.params import ParamSpec


@dataclass(frozen=True)
class FakeParams:
    """Fake settings; ``label``: what the node is called."""

    rate: float = 10.0     # Hz: how often it ticks
    width: float = 0.25    # m, wheel separation
    label: str = "fake"
    ticks: int = 3         # counter without unit
{extra}

SPEC = ParamSpec(FakeParams, {{"rate": "~rate", "width": ("~width", "width"), "label": "~label", "ticks": "~ticks"
                              {extra_names}}})
PARAMS = (SPEC,)


def main() -> int:
    raise SystemExit("must not run on import")


if __name__ == "__main__":
    main()
'''
LAUNCH = '''<launch>
  <rosparam file="$(find fakepkg)/param/shared.yaml" command="load"/>
  <node pkg="fakepkg" type="fakenode" name="fakenode">
    <rosparam file="$(arg params)" command="load"/>
  </node>
  <arg name="params" default="$(find fakepkg)/param/fake.yaml"/>
</launch>
'''


@pytest.fixture
def fake(tmp_path, monkeypatch):
    pkg = tmp_path / "fakepkg"
    (pkg / "nodes").mkdir(parents=True)
    (pkg / "param").mkdir()
    (pkg / "launch").mkdir()
    (pkg / "package.xml").write_text("<package><name>fakepkg</name></package>")
    (pkg / "launch" / "fake.launch").write_text(LAUNCH)
    (pkg / "param" / "fake.yaml").write_text("rate: 20.0   # [Hz] tick rate\nticks: 3\n")
    (pkg / "param" / "shared.yaml").write_text("width: 0.3   # [m] shared track\n")
    (pkg / "README.md").write_text("# fakepkg\n\n### fakenode\n<!-- BEGIN generated params fakepkg/fakenode -->\n"
                                   "<!-- END generated params -->\n\nMore text.\n")
    monkeypatch.setattr(gen, "ROOT", tmp_path)

    def write_node(extra: str = "", extra_names: str = "", **replace: str) -> None:
        text = NODE.format(extra=extra, extra_names=extra_names)
        for old, new in replace.items():
            text = text.replace(old, new)
        (pkg / "nodes" / "fakenode").write_text(text)

    write_node()
    return pkg, write_node


def check(**kw) -> list[str]:
    return gen.run(check=True, packages=("fakepkg",), out=io.StringIO(), **kw)


def test_fake_write_then_check_clean(fake) -> None:
    pkg, _ = fake
    assert len(check()) == 1                              # the empty table is stale
    assert gen.run(check=False, packages=("fakepkg",), out=io.StringIO()) == []
    assert check() == []
    text = (pkg / "README.md").read_text()
    assert text.endswith("<!-- END generated params -->\n\nMore text.\n")   # nothing outside the markers
    table = text.split("-->\n", 1)[1].split("<!-- END")[0]
    assert "| `~rate` | float | `20.0` | Hz | how often it ticks; code default `10.0` |" in table
    assert "| `~width` (falls back to `width`) | float | `0.3` | m | wheel separation; code default `0.25` |" in table
    assert "| `~label` | str | `fake` |   | what the node is called |" in table
    assert "| `~ticks` | int | `3` |   | counter without unit |" in table


def test_fake_new_field_fails_check(fake) -> None:
    _, write_node = fake
    gen.run(check=False, packages=("fakepkg",), out=io.StringIO())
    write_node(extra="    timeout: float = 1.0   # s", extra_names=', "timeout": "~timeout"')
    problems = check()
    assert len(problems) == 1 and "stale" in problems[0] and "+| `~timeout` | float | `1.0` | s |" in problems[0]


def test_fake_changed_default_fails_check(fake) -> None:
    _, write_node = fake
    gen.run(check=False, packages=("fakepkg",), out=io.StringIO())
    write_node(**{'label: str = "fake"': 'label: str = "other"'})
    problems = check()
    assert len(problems) == 1 and "-| `~label` | str | `fake`" in problems[0] and "+| `~label` | str | `other`" in \
        problems[0]


def test_fake_missing_and_orphan_markers_reported_not_invented(fake) -> None:
    pkg, _ = fake
    readme = pkg / "README.md"
    readme.write_text("# fakepkg\n\n<!-- BEGIN generated params fakepkg/gone -->\n<!-- END generated params -->\n")
    before = readme.read_text()
    problems = gen.run(check=False, packages=("fakepkg",), out=io.StringIO())
    assert readme.read_text() == before                   # write mode adds no structure
    assert any("no '<!-- BEGIN generated params fakepkg/fakenode -->' markers" in p for p in problems)
    assert any("markers for fakepkg/gone" in p for p in problems)


def test_fake_node_without_params_is_reported(fake) -> None:
    pkg, write_node = fake
    write_node(**{"PARAMS = (SPEC,)": ""})
    problems = check()
    assert any("no module-level PARAMS" in p for p in problems)


def test_split_unit_rule() -> None:
    assert gen.split_unit("Hz: encoder-silence check") == ("Hz", "encoder-silence check")
    assert gen.split_unit("[m] a range above this is a drop") == ("m", "a range above this is a drop")
    assert gen.split_unit("m, round robot") == ("m", "round robot")
    assert gen.split_unit("encoder ticks per metre of wheel travel (ticks/m)") == \
        ("ticks/m", "encoder ticks per metre of wheel travel")
    assert gen.split_unit("[[x, y, yaw], ...] poses") == ("", "[[x, y, yaw], ...] poses")
    assert gen.split_unit("frontier | waypoints") == ("", "frontier | waypoints")


def test_field_comments_with_continuation(tmp_path) -> None:
    src = textwrap.dedent('''
        from dataclasses import dataclass

        @dataclass
        class C:
            a: float = 1.0   # s: first part
                             #   second part
            b: int = 2       # px
            # a comment about c, not a continuation of b's
            c: str = "x"
        ''')
    path = tmp_path / "_test_node_docs_fields.py"
    path.write_text(src)
    spec = importlib.util.spec_from_file_location("_test_node_docs_fields", path)
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod
    try:
        spec.loader.exec_module(mod)
        assert gen.field_comments(mod.C) == {"a": "s: first part second part", "b": "px"}
    finally:
        sys.modules.pop(spec.name, None)

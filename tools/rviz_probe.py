#!/usr/bin/env python3
"""Open an RViz config in a real RViz window and report every display's status.

RViz offers no outside API for a display's status (the "Status: Ok/Warn/Error"
line of the Displays panel), so this loads the config into RViz's own
``VisualizationFrame`` through Debian's ``python3-rviz`` bindings (librviz, the
library /usr/bin/rviz is built on) and walks the display tree: every display
has a "Status" property whose value is ``Ok``/``Warn``/``Error`` and whose
children are the individual entries ("Transform" -> "No transform from [a]
to [b]", "Topic" -> "N messages received", ...). The root display group's
"Global Status" (fixed frame) is checked too. RViz 1 leaves a message display
(LaserScan, Path, ...) at Ok with "Topic: OK" until its first message arrives;
the probe reports that as Warn "No messages received", so a topic nobody
publishes fails the check.

Needs an X display (run it under ``xvfb-run -a``) and a master with the data
the config shows. Waits until every enabled display is Ok (or ``--timeout``
wall seconds pass), saves a screenshot of the window then (``--screenshot``;
at the timeout if never), checks that all stay Ok for ``--settle`` s, and
prints one JSON object: ``{"ok": bool, "displays": [{"name", "class",
"status", "entries": {name: text}}, ...], "wall_s_to_ok": s}`` (when the
last all-Ok stretch began, wall s after loading). Exit code 0 when all are
Ok, 1 when some are not, 2 on a bad config or no display.

Usage: python tools/rviz_probe.py CONFIG.rviz [--timeout 60] [--settle 3]
       [--screenshot out.png] [--size 1280x800]
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path


def _children(prop) -> list:
    return [prop.childAt(i) for i in range(prop.numChildren())]


def status_of(prop) -> tuple[str, dict]:
    """(``Ok``/``Warn``/``Error``, {entry name: text}) of a display or the root group.

    The bindings hand out plain ``Property`` objects; a status list is the child named
    ``Status: <level>`` (``Global Status: <level>`` on the root group), one child per entry.
    A display that never set a status has no such child: nothing to complain about (Ok)."""
    for child in _children(prop):
        name = str(child.getName())
        if name.startswith(("Status:", "Global Status:")):
            entries = {str(e.getName()): str(e.getValue()) for e in _children(child)}
            return name.split(":", 1)[1].strip(), entries
    return "Ok", {}


def config_classes(config: Path) -> dict[str, str]:
    """Display name -> class (e.g. ``rviz/LaserScan``) from the .rviz YAML (the bindings hide it)."""
    import yaml

    doc = yaml.safe_load(config.read_text()) or {}
    out: dict[str, str] = {}

    def visit(displays: list) -> None:
        for d in displays or []:
            out[str(d.get("Name", ""))] = str(d.get("Class", ""))
            visit(d.get("Displays"))

    visit((doc.get("Visualization Manager") or {}).get("Displays"))
    return out


def snapshot(manager, classes: dict[str, str]) -> dict:
    """Status of the root group (fixed frame) and of every enabled display (groups flattened)."""
    root = manager.getRootDisplayGroup()
    level, entries = status_of(root)
    if "Fixed Frame" not in entries:  # RViz has not run its first update yet: nothing is known
        level, entries["Fixed Frame"] = "Warn", "not checked yet (no update so far)"
    displays = [{"name": "Global Status", "class": "", "status": level, "entries": entries}]

    def visit(group) -> None:
        for child in _children(group):
            name = str(child.getName())
            if name not in classes or child.getValue() is not True:
                continue  # a property (Global Options, status list) or a disabled display
            level, entries = status_of(child)
            if entries.get("Topic") == "OK" and "Message" not in entries and level == "Ok":
                # RViz 1 keeps a subscribed message display Ok until its first message (then
                # "N messages received"); ROS 2's "No messages received" warning is ours here
                level, entries["Topic"] = "Warn", "No messages received (subscribed, nothing arrived)"
            displays.append({"name": name, "class": classes[name], "status": level, "entries": entries})
            if classes[name] == "rviz/Group":
                visit(child)

    visit(root)
    return {"ok": all(d["status"] == "Ok" for d in displays), "displays": displays}


def save_screenshot(app, frame, path: Path) -> bool:
    """Render a few more frames, then save the window as a PNG; False (said on stderr) if it fails."""
    for _ in range(10):
        app.processEvents()
        time.sleep(0.05)
    path.parent.mkdir(parents=True, exist_ok=True)
    if not app.primaryScreen().grabWindow(int(frame.winId())).save(str(path)):
        print(f"rviz_probe: cannot save screenshot {path}", file=sys.stderr)
        return False
    return True


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("config", type=Path, help=".rviz file")
    ap.add_argument("--timeout", type=float, default=60.0, help="wall seconds to wait for all Ok")
    ap.add_argument("--settle", type=float, default=3.0,
                    help="wall seconds all displays must stay Ok before the verdict")
    ap.add_argument("--screenshot", type=Path, help="save a PNG of the RViz window here")
    ap.add_argument("--size", default="1280x800", help="window size WxH, px")
    args = ap.parse_args(argv)
    if not args.config.is_file():
        print(f"rviz_probe: config file {args.config} not found", file=sys.stderr)
        return 2
    if not os.environ.get("DISPLAY"):
        print("rviz_probe: no DISPLAY (run under xvfb-run -a)", file=sys.stderr)
        return 2
    try:
        w, h = (int(v) for v in args.size.lower().split("x"))
    except ValueError:
        print(f"rviz_probe: --size must be WxH, got {args.size!r}", file=sys.stderr)
        return 2

    # Ogre draws into a native X window: Qt's offscreen platform (the test runner sets it for
    # the GUI tests) gives it none ("Invalid parentWindowHandle")
    os.environ["QT_QPA_PLATFORM"] = "xcb"
    from python_qt_binding.QtWidgets import QApplication
    from rviz import bindings as rviz

    app = QApplication([sys.argv[0]])
    frame = rviz.VisualizationFrame()
    frame.setSplashPath("")
    frame.initialize()
    config = rviz.Config()
    reader = rviz.YamlConfigReader()
    reader.readFile(config, str(args.config))
    if reader.error():
        print(f"rviz_probe: cannot read {args.config}: {reader.errorMessage()}", file=sys.stderr)
        return 2
    frame.load(config)
    classes = config_classes(args.config)
    frame.resize(w, h)
    frame.show()
    manager = frame.getManager()

    t0 = time.monotonic()
    deadline = t0 + args.timeout
    ok_since = None
    shot_ok = args.screenshot is None
    snap = snapshot(manager, classes)
    while time.monotonic() < deadline:
        app.processEvents()
        time.sleep(0.05)
        snap = snapshot(manager, classes)
        if not snap["ok"]:
            ok_since = None
            continue
        if ok_since is None:
            ok_since = time.monotonic()
            snap_first_ok_s = ok_since - t0
            if not shot_ok:  # the picture as soon as all is Ok (a robot on its way, not arrived)
                shot_ok = save_screenshot(app, frame, args.screenshot)
        elif time.monotonic() - ok_since >= args.settle:
            break
    if not shot_ok:  # never all Ok: a picture of what is wrong
        shot_ok = save_screenshot(app, frame, args.screenshot)
    snap["ok"] = snap["ok"] and shot_ok and ok_since is not None
    snap["wall_s_to_ok"] = round(snap_first_ok_s, 1) if ok_since is not None else None
    print(json.dumps(snap, indent=1), flush=True)
    frame.hide()
    # librviz's teardown (Ogre, ros::shutdown) can hang or crash on some machines: the verdict
    # is printed, so leave without it
    os._exit(0 if snap["ok"] else 1)


if __name__ == "__main__":
    sys.exit(main())

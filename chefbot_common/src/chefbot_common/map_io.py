"""Read and write maps in the ``map_server`` YAML + image format (pure).

Semantics follow ROS map_server's image loader: the image's top row is the
map's largest y; a pixel's channels are averaged (integer mean), optionally
negated (``negate``), then

* ``trinary`` (default): p = (255 - v) / 255; p > occupied_thresh -> 100,
  p < free_thresh -> 0, otherwise -1;
* ``scale``: as trinary, but values between the thresholds become
  1 + 98 * (p - free) / (occ - free), and a transparent pixel (alpha < 255)
  is -1;
* ``raw``: the value itself (0..255, stored as int8, so 255 is -1).

The saver writes like ``map_saver``: free (0) -> 254, occupied (>= 65) -> 0,
everything else -> 205, with thresholds 0.65 / 0.196 in the YAML, so that
load -> save -> load is the identity for trinary maps.
"""
from __future__ import annotations

import math
import os
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import yaml
from PIL import Image

from chefbot_common.grid import GridInfo, OccupancyMap

MODES = ("trinary", "scale", "raw")
REQUIRED = ("image", "resolution", "origin", "negate", "occupied_thresh", "free_thresh")
# Largest map accepted by default: 4000 x 4000 cells (200 m x 200 m at 0.05 m/cell,
# a hotel floor). A 20000 x 20000 map took 25 s and 4.8 GB to load, and every
# costmap copy of it gigabytes more: refuse such maps with a clear message instead.
MAX_MAP_CELLS = 4000 * 4000
# Sane resolutions (m/cell): finer than 1 mm or coarser than 100 m is a typo.
RESOLUTION_RANGE = (1e-3, 100.0)


class MapError(ValueError):
    """A map file cannot be used; the message names the file and the field."""


def _as_float(value: Any) -> float | None:
    """``value`` as a finite float, or None.

    YAML 1.1 (PyYAML) reads ``1e-300`` (no dot) as a string, where map_server's
    yaml-cpp reads a number: accept numeric strings too.
    """
    if isinstance(value, bool):
        return None
    if isinstance(value, str):
        try:
            value = float(value.strip())
        except ValueError:
            return None
    if not isinstance(value, (int, float)) or not math.isfinite(value):
        return None
    return float(value)


def _number(path: Path, meta: dict[str, Any], field: str) -> float:
    value = _as_float(meta[field])
    if value is None:
        raise MapError(f"{path}: field '{field}' must be a finite number, got {meta[field]!r}")
    return value


def read_map_yaml(path: str | os.PathLike) -> dict[str, Any]:
    """Parse and validate a map YAML; returns the fields with ``image`` made absolute.

    Raises :class:`MapError` naming the file and the offending field.
    """
    path = Path(path)
    try:
        text = path.read_bytes().decode("utf-8")
    except IsADirectoryError as exc:
        raise MapError(f"{path}: is a directory, not a map YAML file") from exc
    except OSError as exc:
        raise MapError(f"{path}: cannot read map YAML ({exc.strerror or exc})") from exc
    except UnicodeDecodeError as exc:
        raise MapError(f"{path}: not a text file (byte {exc.start} is not UTF-8); "
                       "a map YAML is UTF-8 text") from exc
    try:
        meta = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise MapError(f"{path}: not valid YAML ({exc})") from exc
    if not isinstance(meta, dict):
        raise MapError(f"{path}: a map YAML must be a mapping with fields {', '.join(REQUIRED)}")
    for field in REQUIRED:
        if field not in meta:
            raise MapError(f"{path}: missing field '{field}'")
    out: dict[str, Any] = {}
    image = meta["image"]
    if not isinstance(image, str) or not image.strip():
        raise MapError(f"{path}: field 'image' must be a file name, got {image!r}")
    image_path = Path(os.path.expanduser(image))
    if not image_path.is_absolute():
        image_path = path.parent / image_path
    out["image"] = image_path
    out["resolution"] = _number(path, meta, "resolution")
    lo, hi = RESOLUTION_RANGE
    if not lo <= out["resolution"] <= hi:
        raise MapError(f"{path}: field 'resolution' must be between {lo:g} and {hi:g} m/cell, "
                       f"got {out['resolution']:g}")
    origin = meta["origin"]
    values = [_as_float(v) for v in origin] if isinstance(origin, (list, tuple)) else []
    if len(values) != 3 or any(v is None for v in values):
        raise MapError(f"{path}: field 'origin' must be [x, y, yaw] (3 finite numbers), got {origin!r}")
    out["origin"] = values
    negate = meta["negate"]
    if negate not in (0, 1) or (isinstance(negate, float)):
        raise MapError(f"{path}: field 'negate' must be 0 or 1, got {negate!r}")
    out["negate"] = bool(negate)
    for field in ("occupied_thresh", "free_thresh"):
        out[field] = _number(path, meta, field)
        if not 0.0 <= out[field] <= 1.0:
            raise MapError(f"{path}: field '{field}' must be in [0, 1], got {meta[field]!r}")
    if out["free_thresh"] > out["occupied_thresh"]:
        raise MapError(f"{path}: field 'free_thresh' ({out['free_thresh']}) must not exceed "
                       f"'occupied_thresh' ({out['occupied_thresh']})")
    mode = meta.get("mode", "trinary")
    if mode not in MODES:
        raise MapError(f"{path}: field 'mode' must be one of {', '.join(MODES)}, got {mode!r}")
    out["mode"] = mode
    return out


def image_to_occupancy(image: np.ndarray, negate: bool, occupied_thresh: float, free_thresh: float,
                       mode: str = "trinary") -> np.ndarray:
    """Convert an image (H, W) or (H, W, C) uint8/uint16 to OccupancyGrid values.

    Returns int8 (H, W) in OccupancyGrid row order (row 0 = bottom of the image).
    """
    img = np.asarray(image)
    if img.dtype == np.uint16:
        img = (img >> 8).astype(np.uint8)   # keep the top byte, as an 8-bit loader would
    alpha = None
    if img.ndim == 3:
        channels = img.shape[2]
        if channels in (2, 4):
            alpha, img = img[:, :, -1], img[:, :, :-1]
        # map_server averages the colour channels with an integer division
        value = img.astype(np.uint16).sum(axis=2) // img.shape[2]
    else:
        value = img.astype(np.uint16)
    if negate:
        value = 255 - value
    if mode == "raw":
        out = value.astype(np.uint8).view(np.int8)
        return np.ascontiguousarray(out[::-1])
    p = (255.0 - value) / 255.0
    out = np.full(value.shape, -1, dtype=np.int8)
    if mode == "scale":
        denom = max(occupied_thresh - free_thresh, 1e-12)
        ratio = np.clip((p - free_thresh) / denom, 0.0, 1.0)
        out[:] = (1 + 98 * ratio).astype(np.int8)   # truncation, like map_server's int cast
        if alpha is not None:
            out[alpha < 255] = -1
    out[p > occupied_thresh] = 100
    out[p < free_thresh] = 0
    return np.ascontiguousarray(out[::-1])


def image_size(path: str | os.PathLike) -> tuple[int, int]:
    """(width, height) in pixels from an image file's header, without decoding the pixels.

    Raises :class:`MapError` when the header cannot be read.
    """
    # Only the header is read, so Pillow's decompression-bomb guard (which would
    # refuse to even report a huge size) is lifted here; the caller checks the size.
    guard, Image.MAX_IMAGE_PIXELS = Image.MAX_IMAGE_PIXELS, None
    try:
        with Image.open(path) as im:
            return im.size
    except (OSError, ValueError, SyntaxError) as exc:
        raise MapError(f"{path}: not a readable image ({exc})") from exc
    finally:
        Image.MAX_IMAGE_PIXELS = guard


def check_map_size(width: int, height: int, max_cells: int, where: str) -> None:
    """Raise :class:`MapError` when a ``width`` x ``height`` grid exceeds ``max_cells`` or is empty."""
    if width < 1 or height < 1:
        raise MapError(f"{where}: map is empty ({width} x {height} cells)")
    if width * height > max_cells:
        raise MapError(f"{where}: map is {width} x {height} = {width * height:,} cells, more than the "
                       f"maximum of {max_cells:,} cells (param max_map_cells); crop it or use a coarser "
                       "resolution")


def load_map(yaml_path: str | os.PathLike, max_cells: int = MAX_MAP_CELLS) -> OccupancyMap:
    """Load a map_server YAML + image into an :class:`OccupancyMap`.

    Raises :class:`MapError` naming the file and field for every kind of bad
    input (missing/unreadable/corrupt image, bad or missing YAML fields, an
    image larger than ``max_cells`` cells, checked from its header before decoding).
    """
    meta = read_map_yaml(yaml_path)
    image_path: Path = meta["image"]
    if image_path.is_dir():
        raise MapError(f"{yaml_path}: field 'image': {image_path} is a directory, not an image file")
    if not image_path.is_file():
        raise MapError(f"{yaml_path}: field 'image': file {image_path} does not exist")
    try:
        width, height = image_size(image_path)
    except MapError as exc:
        raise MapError(f"{yaml_path}: field 'image': {exc}") from exc
    check_map_size(width, height, max_cells, f"{yaml_path}: field 'image': {image_path}")
    try:
        image = cv2.imread(str(image_path), cv2.IMREAD_UNCHANGED)
    except cv2.error as exc:
        raise MapError(f"{yaml_path}: field 'image': {image_path} cannot be decoded ({exc.err})") from exc
    if image is None or image.size == 0:
        raise MapError(f"{yaml_path}: field 'image': {image_path} is not a readable image (corrupt or "
                       "unsupported format)")
    data = image_to_occupancy(image, meta["negate"], meta["occupied_thresh"], meta["free_thresh"], meta["mode"])
    height, width = data.shape
    ox, oy, oyaw = meta["origin"]
    info = GridInfo(meta["resolution"], width, height, ox, oy, oyaw)
    return OccupancyMap(info, data)


def occupancy_to_image(data: np.ndarray, occupied: int = 65, free: int = 25) -> np.ndarray:
    """map_saver's conversion: 0..free -> 254, >= occupied -> 0, else 205; image row order."""
    d = np.asarray(data, dtype=np.int16)
    img = np.full(d.shape, 205, dtype=np.uint8)
    img[(d >= 0) & (d <= free)] = 254
    img[d >= occupied] = 0
    return np.ascontiguousarray(img[::-1])


def write_pgm(path: str | os.PathLike, image: np.ndarray, comment: str = "") -> None:
    """Write an 8-bit binary PGM (P5)."""
    img = np.ascontiguousarray(image, dtype=np.uint8)
    header = "P5\n" + (f"# {comment}\n" if comment else "") + f"{img.shape[1]} {img.shape[0]}\n255\n"
    with open(path, "wb") as f:
        f.write(header.encode("ascii"))
        f.write(img.tobytes())


def read_pgm(path: str | os.PathLike) -> np.ndarray:
    """Read an 8-bit grey image (binary PGM or any format OpenCV reads) as uint8 (H, W), top row first."""
    img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if img is None or img.size == 0:
        raise MapError(f"{path}: not a readable image (missing, corrupt or unsupported format)")
    if img.dtype != np.uint8 or img.ndim != 2:
        raise MapError(f"{path}: expected an 8-bit single-channel image, got {img.dtype} {img.shape}")
    return img


def write_map_yaml(path: str | os.PathLike, image_name: str, resolution: float,
                   origin: tuple[float, float, float]) -> None:
    """Write a map_server YAML (trinary thresholds 0.65 / 0.196, negate 0) for ``image_name``."""
    ox, oy, oyaw = origin
    Path(path).write_text(f"image: {image_name}\n"
                          f"resolution: {resolution!r}\n"
                          f"origin: [{ox!r}, {oy!r}, {oyaw!r}]\n"
                          "negate: 0\n"
                          "occupied_thresh: 0.65\n"
                          "free_thresh: 0.196\n")


def save_map(occ: OccupancyMap, base: str | os.PathLike, occupied: int = 65, free: int = 25) -> tuple[Path, Path]:
    """Write ``base.pgm`` and ``base.yaml`` like map_saver; returns both paths.

    ``occupied``/``free`` are the OccupancyGrid thresholds (0..100) of the
    conversion; the YAML always says 0.65 / 0.196 so that reloading gives
    exactly 100 / 0 / -1 back.
    """
    base = Path(base)
    if base.suffix in (".yaml", ".pgm"):
        base = base.with_suffix("")
    base.parent.mkdir(parents=True, exist_ok=True)
    pgm, yml = base.with_suffix(".pgm"), base.with_suffix(".yaml")
    info = occ.info
    write_pgm(pgm, occupancy_to_image(occ.data, occupied, free),
              f"CREATOR: chefbot_navigation map_saver {info.resolution:.3f} m/pix")
    write_map_yaml(yml, pgm.name, info.resolution, (info.origin_x, info.origin_y, info.origin_yaw))
    return yml, pgm

"""Reader of ``firmware/protocol_vectors.txt``, the serial-protocol golden
strings shared by the firmware's C++ tests and the PC side's Python tests
(format: firmware/PROTOCOL.md, "Test vectors")."""
from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path


@dataclass(frozen=True)
class CrcVector:
    """A CRC-8 test vector: data, expected CRC and its line in the file."""

    data: bytes
    crc: int
    line_no: int


@dataclass(frozen=True)
class RxVector:
    """Bytes sent PC→board and the events the board's parser must produce:
    ("s", left, right), ("r",), ("empty",), ("error", class)."""

    data: bytes
    events: tuple[tuple, ...]
    line_no: int


@dataclass(frozen=True)
class TxVector:
    """A board→PC line: ``kind`` is "tx" (default config, with checksum),
    "plain" (checksum off) or "book" (the book's firmware); ``tag`` and
    ``values`` (strings, as a parser should read them) and the exact bytes."""

    kind: str
    tag: str
    values: tuple[str, ...]
    line: bytes
    line_no: int


@dataclass(frozen=True)
class Vectors:
    """All test vectors of protocol_vectors.txt, by kind."""

    crc: tuple[CrcVector, ...]
    rx: tuple[RxVector, ...]
    tx: tuple[TxVector, ...]


def vectors_path() -> Path:
    """Path of the shared protocol_vectors.txt."""
    return Path(os.path.realpath(__file__)).parents[2] / "protocol_vectors.txt"


def unescape(text: str) -> bytes:
    r"""Decode the file's escapes: \t \r \n \\ \xHH."""
    out = bytearray()
    i = 0
    simple = {"t": b"\t", "r": b"\r", "n": b"\n", "\\": b"\\"}
    while i < len(text):
        c = text[i]
        if c != "\\":
            out += c.encode("ascii")
            i += 1
            continue
        nxt = text[i + 1: i + 2]
        if nxt in simple:
            out += simple[nxt]
            i += 2
        elif nxt == "x":
            out.append(int(text[i + 2: i + 4], 16))
            i += 4
        else:
            raise ValueError(f"bad escape in {text!r}")
    return bytes(out)


def _event(text: str) -> tuple:
    parts = text.split(" ")
    if parts[0] == "s":
        return ("s", int(parts[1]), int(parts[2]))
    if parts[0] == "error":
        return ("error", parts[1])
    return (parts[0],)


def load_vectors(path: Path | None = None) -> Vectors:
    """Parse protocol_vectors.txt (or ``path``) into :class:`Vectors`."""
    crc, rx, tx = [], [], []
    for no, raw in enumerate((path or vectors_path()).read_text(encoding="ascii").splitlines(), start=1):
        if not raw or raw.startswith("#"):
            continue
        kind, *cols = raw.split("\t")
        if len(cols) != 2:
            raise ValueError(f"{path or vectors_path()}:{no}: expected 3 TAB-separated columns")
        if kind == "crc":
            crc.append(CrcVector(unescape(cols[0]), int(cols[1], 16), no))
        elif kind == "rx":
            events = () if cols[1] == "none" else tuple(_event(e) for e in cols[1].split("; "))
            rx.append(RxVector(unescape(cols[0]), events, no))
        elif kind in ("tx", "plain", "book"):
            tag, *values = cols[0].split(" ")
            tx.append(TxVector(kind, tag, tuple(values), unescape(cols[1]), no))
        else:
            raise ValueError(f"{path or vectors_path()}:{no}: unknown vector kind {kind!r}")
    return Vectors(tuple(crc), tuple(rx), tuple(tx))

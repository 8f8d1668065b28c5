"""protocol_vectors.txt is well-formed and its checksums are right, computed
independently of the C++ code."""
from __future__ import annotations

from chefbot_firmware.protocol_vectors import load_vectors, unescape, vectors_path


def crc8(data: bytes) -> int:
    crc = 0
    for byte in data:
        crc ^= byte
        for _ in range(8):
            crc = ((crc << 1) ^ 0x07) & 0xFF if crc & 0x80 else (crc << 1) & 0xFF
    return crc


def test_file_has_every_kind():
    v = load_vectors()
    assert vectors_path().is_file()
    assert len(v.crc) >= 3 and len(v.rx) >= 40
    assert {t.kind for t in v.tx} == {"tx", "plain", "book"}


def test_crc_vectors():
    for c in load_vectors().crc:
        assert crc8(c.data) == c.crc, c


def test_tx_lines_are_tab_separated_with_valid_checksum_and_values():
    for t in load_vectors().tx:
        assert t.line.endswith(b"\n") and t.line.count(b"\n") == 1, t
        parts = t.line[:-1].decode("ascii").split("\t")
        if t.kind == "tx":
            token = parts.pop()
            assert token.startswith("*") and len(token) == 3, t
            assert int(token[1:], 16) == crc8(t.line[: t.line.rfind(b"\t")]), t
        assert parts[0] == t.tag
        # A book-style parser reads the first N fields as numbers.
        for got, want in zip(parts[1:], t.values, strict=False):
            try:
                assert float(got) == float(want), t
            except ValueError:
                assert got == want, t


def test_rx_commands_with_checksum_are_right():
    for r in load_vectors().rx:
        if b" *" in r.data and r.events and r.events[0][0] in ("s", "r"):
            line = r.data.rstrip(b"\r\n")
            body, token = line.rsplit(b" ", 1)
            assert int(token[1:], 16) == crc8(body.rstrip(b" \t")), r


def test_unescape():
    assert unescape(r"a\tb\r\n\\\x00\xff") == b"a\tb\r\n\\\x00\xff"

"""One species file → Params: bytes checked, then the text or the XML reader, by content."""

from __future__ import annotations

from pathlib import Path

from ..errors import TreegenError
from .arbaro_xml import parse_params_xml
from .record import Params
from .text import parse_params_text


def _looks_xml(text: str) -> bool:
    return text.lstrip("\ufeff \t\r\n").startswith("<")


def parse_params_bytes(data: bytes, source: str = "<string>", partial: bool = False) -> Params:
    """Parse a species file's raw bytes: Arbaro XML if it starts with '<', else text (which
    must list every parameter unless `partial`; Arbaro XML is partial by design)."""
    if data[:4] in (b"\xff\xfe\x00\x00", b"\x00\x00\xfe\xff"):
        raise TreegenError(f"{source}:1: UTF-32 text; save it as UTF-8")
    if data[:2] in (b"\xff\xfe", b"\xfe\xff"):  # UTF-16 with its byte-order mark (Notepad's
        # "Unicode"): expat reads such XML itself; text is decoded here
        try:
            text = data.decode("utf-16")
        except UnicodeDecodeError as exc:
            raise TreegenError(
                f"{source}: not valid UTF-16 text (at byte {exc.start}; cut short?); save it as UTF-8"
            ) from None
        if text.lstrip("\ufeff \t\r\n").startswith("<"):
            return parse_params_xml(data, source)
        data = text.encode("utf-8")
    if b"\x00" in data:
        line = data.count(b"\n", 0, data.index(b"\x00")) + 1
        head = data[:64]
        if len(head) > 8 and (
            head[1::2].count(0) > 0.8 * len(head[1::2]) or head[::2].count(0) > 0.8 * len(head[::2])
        ):
            raise TreegenError(f"{source}:{line}: UTF-16 text without a byte-order mark; save it as UTF-8")
        raise TreegenError(f"{source}:{line}: binary data (NUL byte): not a species file")
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        if data.lstrip().startswith(b"<?xml") and b"encoding" in data[:200]:
            return parse_params_xml(data, source)  # declared non-UTF-8 encoding: expat decodes
        line = data.count(b"\n", 0, exc.start) + 1
        raise TreegenError(
            f"{source}:{line}: not UTF-8 text (byte 0x{data[exc.start]:02x} "
            f"at offset {exc.start}): binary file?"
        ) from None
    if not text.strip():
        raise TreegenError(f"{source}:1: empty species file: no parameters found")
    if _looks_xml(text):
        return parse_params_xml(data, source)
    if "\r" in text and "\n" not in text:  # classic Mac line ends: lines end in CR alone
        text = text.replace("\r", "\n")
    return parse_params_text(text, source, partial)


def _read_as_text(data: bytes) -> bool:
    """Whether parse_params_bytes gave `data` to the Weber–Penn text reader (UTF-8 text, no
    NUL, not starting with '<'), rather than refusing its bytes or reading it as XML."""
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError:
        return False
    return "\x00" not in text and bool(text.strip()) and not _looks_xml(text)


def load_params(path: str | Path) -> Params:
    """Read and validate one species file (text or Arbaro XML, decided by content)."""
    p = Path(path)
    source = str(path)
    if p.is_dir():
        raise TreegenError(f"{source}: is a directory, expected a species file")
    try:
        data = p.read_bytes()
    except FileNotFoundError:
        raise TreegenError(f"{source}: no such species file") from None
    except OSError as exc:
        raise TreegenError(f"{source}: cannot read species file: {exc.strerror or exc}") from None
    try:
        return parse_params_bytes(data, source)
    except TreegenError as exc:  # an .xml that is not XML was read as text: say so
        if p.suffix.lower() != ".xml" or not _read_as_text(data):
            raise
        raise TreegenError(
            f"{exc} (this .xml file does not start with '<', so it is not Arbaro XML and was read "
            "as Weber–Penn text)"
        ) from None

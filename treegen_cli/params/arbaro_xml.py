"""Arbaro's XML species files: `<arbaro><species name=..><param name=.. value=../>`.

Read with expat directly (as ElementTree does) to keep each param's line number for errors;
DOCTYPE and ENTITY declarations are refused outright: no entity expansion, no external resources.
"""

from __future__ import annotations

from xml.parsers import expat

from ..errors import TreegenError
from .assemble import Builder, clip, default_name, printable
from .record import Params


class _Refused(Exception):
    """Raised inside expat callbacks; turned into a TreegenError by the caller."""


def parse_params_xml(data: str | bytes, source: str = "<string>") -> Params:
    """Read an Arbaro species file (`<arbaro><species name=..><param name=.. value=../>`).

    Uses expat directly (as ElementTree does) to keep each param's line number. DOCTYPE and
    ENTITY declarations are refused outright: no entity expansion, no external resources.
    """
    b = Builder(source)
    p = expat.ParserCreate()
    p.SetParamEntityParsing(expat.XML_PARAM_ENTITY_PARSING_NEVER)
    stack: list[str] = []
    species_count = 0

    def refuse(msg: str):
        raise _Refused(f"{b.where(p.CurrentLineNumber)}: {printable(clip(msg, 200))}")

    def start(tag: str, attrs: dict[str, str]):
        nonlocal species_count
        line = p.CurrentLineNumber
        if not stack and tag != "arbaro":
            refuse(f"root element is <{tag}>, expected <arbaro> (an Arbaro species file)")
        if tag == "species":
            species_count += 1
            if species_count > 1:
                refuse("more than one <species>; treegen reads one species per file")
            if "name" in attrs:
                b.set_name(attrs["name"], line, "species name")
        elif tag == "param":
            if "species" not in stack:
                refuse("<param> outside <species>")
            if "name" not in attrs or "value" not in attrs:
                missing = "name" if "name" not in attrs else "value"
                what = attrs.get("name", "")
                refuse(f"<param{' ' + what if what else ''}> has no {missing}= attribute")
            b.add(attrs["name"], attrs["value"], line)
        stack.append(tag)

    def end(tag: str):
        stack.pop()

    def doctype(*_args):
        refuse("DOCTYPE declarations are not allowed in species files (entity expansion risk)")

    def entity(*_args):
        refuse("ENTITY declarations are not allowed in species files")

    p.StartElementHandler = start
    p.EndElementHandler = end
    p.StartDoctypeDeclHandler = doctype
    p.EntityDeclHandler = entity
    p.ExternalEntityRefHandler = lambda *a: refuse("external entities are not allowed")
    try:
        p.Parse(data, True)
    except _Refused as exc:
        raise TreegenError(str(exc)) from None
    except expat.ExpatError as exc:
        raise TreegenError(
            f"{source}:{exc.lineno}:{exc.offset + 1}: malformed XML: {expat.ErrorString(exc.code)}"
        ) from None
    except TreegenError:
        raise
    except (ValueError, UnicodeError, LookupError) as exc:  # e.g. unknown encoding declaration
        raise TreegenError(f"{source}: unreadable XML: {printable(clip(str(exc), 200))}") from None
    if species_count == 0:
        raise b.fail(None, "no <species> element: not an Arbaro species file")
    return b.build(default_name(source))

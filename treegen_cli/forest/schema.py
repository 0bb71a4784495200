"""The layout file's JSON Schema (package data) and a small interpreter of the subset it uses
(type, properties, required, additionalProperties, items, min/maxItems, minimum/maximum,
exclusive bounds, minLength, $ref, anyOf), so the published schema and the checks cannot drift
apart. Every message starts with the JSON path of the offending value (a list's item by its
index: `entries[0].seeds[0]`), and an unknown key names the closest allowed one.

The camera, wind and defaults objects are dataclasses here; their defaults (the wind's and the
screen's read from the stage DEFAULTS) are written into the schema as it is loaded, so the
published "default"s are never typed twice.
"""

from __future__ import annotations

import difflib
import json
import math
from dataclasses import MISSING, dataclass, fields
from importlib import resources
from pathlib import Path

from ..errors import TreegenError
from ..generate import DEFAULTS as GENERATE_DEFAULTS
from ..lod import LOD_DEFAULTS
from ..wind import DEFAULTS as WIND_DEFAULTS

SCHEMA_NAME = "layout.schema.json"
FOREST_LOOP_S = 4.0  # a forest's wind loop: shorter than make's (many trees share one file)
FOREST_MAX_JOINTS = 48  # joints per prototype: a forest's trees are seen from afar


@dataclass(frozen=True)
class Camera:
    position: tuple[float, float, float]
    target: tuple[float, float, float]
    fov_deg: float = LOD_DEFAULTS.fov_deg
    width_px: int = LOD_DEFAULTS.width


@dataclass(frozen=True)
class WindSpec:
    """The layout's "wind" object: one field for the whole forest (wind.WindOptions per tree)."""

    speed: float = WIND_DEFAULTS.speed
    direction_deg: float = WIND_DEFAULTS.direction_deg
    gust: float = WIND_DEFAULTS.gust
    turbulence: float = WIND_DEFAULTS.turbulence
    duration: float = FOREST_LOOP_S
    fps: float = WIND_DEFAULTS.fps
    seed: int = 0
    phase_jitter: float = 0.25
    enabled: bool = True


@dataclass(frozen=True)
class Defaults:
    seed: int = 0
    scale: float = 1.0
    rotation_deg: float = 0.0
    max_joints: int = FOREST_MAX_JOINTS
    lod_distances: tuple[float, ...] | None = LOD_DEFAULTS.distances
    impostor_distance: float | None = None
    error_px: float = LOD_DEFAULTS.error_px
    phase_variants: int = 4
    profile: str | None = None  # forest/options.py: the prototypes' budgets and sizes
    triangles: int | None = None
    max_size: float = GENERATE_DEFAULTS.max_size


# the schema's objects whose "default"s the dataclasses define
DOCUMENTED = {"camera": Camera, "wind": WindSpec, "defaults": Defaults}


def read_json_file(path: Path, kind: str):
    """The decoded JSON of a `kind` file ("layout", "catalogue"), or the one-line error naming
    the file (and line and column for bad JSON). NaN/Infinity literals decode to NaN, which the
    schema's finite-number check then reports at its JSON path."""
    try:
        text = path.read_text("utf-8-sig")  # a byte-order mark (Windows editors) is skipped
    except FileNotFoundError:
        raise TreegenError(f"{path}: no such {kind} file") from None
    except IsADirectoryError:
        raise TreegenError(f"{path}: is a directory; expected a {kind} file (JSON)") from None
    except (OSError, UnicodeDecodeError) as e:
        raise TreegenError(f"{path}: cannot read the {kind} ({e})") from None
    try:
        return json.loads(text, parse_constant=lambda c: float("nan"), object_pairs_hook=_no_duplicates)
    except json.JSONDecodeError as e:
        raise TreegenError(f"{path}: line {e.lineno} column {e.colno}: invalid JSON ({e.msg})") from None
    except _Duplicate as e:
        raise TreegenError(
            f"{path}: key {json.dumps(e.key)} appears twice in one object (JSON keeps only the last: "
            "give it once)"
        ) from None


class _Duplicate(ValueError):
    def __init__(self, key: str):
        super().__init__(key)
        self.key = key


def _no_duplicates(pairs: list) -> dict:
    """A JSON object, refusing a key given twice (json keeps the last silently)."""
    out: dict = {}
    for key, value in pairs:
        if key in out:
            raise _Duplicate(key)
        out[key] = value
    return out


def _json_default(value):
    """4.0 → 4, as the schema has always printed whole numbers."""
    return int(value) if isinstance(value, float) and value.is_integer() else value


def layout_schema() -> dict:
    """The layout schema (package data) with the defaults of DOCUMENTED filled in."""
    text = resources.files("treegen_cli").joinpath("schemas", SCHEMA_NAME).read_text("utf-8")
    schema = json.loads(text)
    for key, cls in DOCUMENTED.items():
        props = schema["properties"][key]["properties"]
        for f in fields(cls):
            if f.default is not MISSING and f.default is not None and f.name in props:
                items = [kv for kv in props[f.name].items() if kv[0] != "default"]
                at = next((i for i, kv in enumerate(items) if kv[0] == "description"), len(items))
                items.insert(at, ("default", _json_default(f.default)))
                props[f.name] = dict(items)
    return schema


def schema_text() -> str:
    """The published JSON Schema of layout files, as `treegen forest --schema` prints it."""
    return json.dumps(layout_schema(), indent=2, ensure_ascii=False) + "\n"


_TYPES = {
    "object": lambda v: isinstance(v, dict),
    "array": lambda v: isinstance(v, list),
    "string": lambda v: isinstance(v, str),
    "boolean": lambda v: isinstance(v, bool),
    "integer": lambda v: isinstance(v, int) and not isinstance(v, bool),
    "number": lambda v: isinstance(v, (int, float)) and not isinstance(v, bool) and _finite(v),
}


def _finite(v) -> bool:
    try:
        return math.isfinite(float(v))
    except OverflowError:  # an integer too large for a float
        return False


def show_value(value) -> str:
    text = json.dumps(value) if not isinstance(value, (dict, list)) else type(value).__name__
    return text if len(text) <= 40 else text[:37] + "..."


def _join(path: str, key) -> str:
    if isinstance(key, int):
        return f"{path}[{key}]"
    return f"{path}.{key}" if path else str(key)


def _num(x) -> str:
    """A bound as written: integers whole (a seed's 9223372036854775807), others short."""
    return str(x) if isinstance(x, int) else f"{x:g}"


def _range(schema: dict) -> str:
    """The bounds of a number schema as an interval: [0, 100], (0, 600], [1, inf)."""
    lo, hi = schema.get("minimum"), schema.get("maximum")
    xlo, xhi = schema.get("exclusiveMinimum"), schema.get("exclusiveMaximum")
    left = f"[{_num(lo)}" if lo is not None else (f"({_num(xlo)}" if xlo is not None else "(-inf")
    right = f"{_num(hi)}]" if hi is not None else (f"{_num(xhi)})" if xhi is not None else "inf)")
    return f"{left}, {right}"


def _json_type(value) -> str:
    if isinstance(value, bool):
        return "boolean"
    if isinstance(value, int):
        return "integer"
    if isinstance(value, float):
        return "number"
    if isinstance(value, str):
        return "string"
    if isinstance(value, list):
        return "array"
    return "object" if isinstance(value, dict) else "null"


def _branch(value, branches: list[dict]) -> dict | None:
    """The anyOf branch of the value's JSON type (an integer fits a number branch; a
    fractional number is checked against an integer branch, to be told it is not whole)."""
    kind = _json_type(value)
    order = {"integer": ("integer", "number"), "number": ("number", "integer")}.get(kind, (kind,))
    for want in order:
        for b in branches:
            if b.get("type") == want:
                return b
    return None


def unknown_key(where: str, key: str, allowed) -> TreegenError:
    """'<path>: unknown key (did you mean X?); allowed: ...', the closest name as for flags
    and species keys (difflib)."""
    names = sorted(allowed)
    by_lower = {n.lower(): n for n in names}
    hit = difflib.get_close_matches(str(key).lower(), list(by_lower), n=1, cutoff=0.6)
    hint = f" (did you mean {by_lower[hit[0]]}?)" if hit else ""
    return TreegenError(f"{where}: unknown key{hint}; allowed: {', '.join(names)}")


def check_schema(value, schema: dict, root: dict, path: str = "") -> None:
    """Raise TreegenError '<json path>: <reason>' at the first place `value` breaks `schema`.
    anyOf checks the branch of the value's type; a value of no branch's type is left to the
    code that reads it, which names what it takes in its own words (batch.parse_seeds)."""
    if "$ref" in schema:
        name = schema["$ref"].rsplit("/", 1)[-1]
        schema = {**root["$defs"][name], **{k: v for k, v in schema.items() if k != "$ref"}}
    if "anyOf" in schema:
        branch = _branch(value, schema["anyOf"])
        if branch is not None:
            check_schema(value, branch, root, path)
    where = path or "(top level)"
    kind = schema.get("type")
    if kind == "integer" and isinstance(value, float) and _finite(value):
        if not value.is_integer():
            bounds = _range(schema)
            allowed = "" if bounds == "(-inf, inf)" else f"; allowed {bounds}"
            raise TreegenError(f"{where}: {show_value(value)} is not a whole number{allowed}")
        write = f" (write {int(value)})" if abs(value) < 2**63 else ""
        raise TreegenError(f"{where}: expected an integer, got {show_value(value)}{write}")
    if kind and not _TYPES[kind](value):
        shown = show_value(value)
        article = "an" if kind[0] in "aeiou" else "a"
        extra = " (finite)" if kind == "number" else ""
        raise TreegenError(f"{where}: expected {article} {kind}{extra}, got {shown}")
    if kind == "number" or kind == "integer":
        lo, hi = schema.get("minimum"), schema.get("maximum")
        xlo, xhi = schema.get("exclusiveMinimum"), schema.get("exclusiveMaximum")
        if (
            (lo is not None and value < lo)
            or (hi is not None and value > hi)
            or (xlo is not None and value <= xlo)
            or (xhi is not None and value >= xhi)
        ):
            raise TreegenError(f"{where}: {show_value(value)} is out of range; allowed {_range(schema)}")
    if kind == "string" and len(value) < schema.get("minLength", 0):
        raise TreegenError(f"{where}: must not be empty")
    if "enum" in schema and value not in schema["enum"]:
        raise TreegenError(
            f"{where}: {show_value(value)}; expected one of {', '.join(map(str, schema['enum']))}"
        )
    if kind == "array":
        n_min, n_max = schema.get("minItems"), schema.get("maxItems")
        if (n_min is not None and len(value) < n_min) or (n_max is not None and len(value) > n_max):
            if n_min == n_max:
                want = f"{n_min}"
            elif n_max is None:
                want = f"at least {n_min}"
            else:
                want = f"{n_min or 0}..{n_max}"
            noun = "item" if want == "1" or want == "at least 1" else "items"
            raise TreegenError(f"{where}: expected {want} {noun}, got {len(value)}")
        if "items" in schema:
            for i, item in enumerate(value):
                check_schema(item, schema["items"], root, _join(path, i))
    if kind == "object":
        props = schema.get("properties", {})
        for key in schema.get("required", []):
            if key not in value:
                typo = [
                    k
                    for k in value
                    if k not in props and difflib.get_close_matches(str(k).lower(), [key.lower()], 1, 0.6)
                ]
                hint = f" (given as {json.dumps(typo[0])}: misspelt?)" if typo else ""
                raise TreegenError(f"{_join(path, key)}: required{hint}")
        for key, item in value.items():
            if key in props:
                check_schema(item, props[key], root, _join(path, key))
            elif schema.get("additionalProperties", True) is False:
                raise unknown_key(_join(path, key), key, props)

"""Property-based fuzzing of every reader a user feeds files to: the species text parser, the
Arbaro XML reader and the forest layout reader. Whatever the bytes, the only exception that may
escape is TreegenError (the CLI turns it into one line and exit 2); anything else is a bug.

Examples per run (derandomized, so CI sees the same cases every time):
  text (structured lines)   1500    XML (structure-aware mutations)  1500
  random bytes / text        600    layout (mutated JSON trees)      1200
  layout random bytes        300                            total    5100
plus a handful of CLI runs with nasty files (no traceback, exit code 2).
"""

from __future__ import annotations

import copy
import json
import math
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from treegen_cli.errors import TreegenError
from treegen_cli.params import (
    LEVEL_ALIASES,
    LEVEL_KEYS,
    MAX_LEVELS,
    TOP_KEYS,
    Params,
    format_params_text,
    parse_params_bytes,
    parse_params_text,
)

ROOT = Path(__file__).resolve().parent.parent
FIXTURES = ROOT / "tests" / "fixtures"
ARBARO = sorted((FIXTURES / "arbaro").glob("*.xml"))

FUZZ = dict(
    deadline=None,
    derandomize=True,
    database=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large, HealthCheck.filter_too_much],
)

# Values chosen to hit every branch of the number checks: non-finite, huge, tiny, negative,
# not-a-number spellings, integers that are not whole, leaf-shape names, junk.
NASTY_VALUES = [
    "nan",
    "NaN",
    "-nan",
    "inf",
    "-inf",
    "Infinity",
    "1e999",
    "-1e999",
    "1e308",
    "-1e308",
    "1.7976931348623157e308",
    "5e-324",
    "-5e-324",
    "0",
    "-0",
    "0.0",
    "-1",
    "1",
    "2.5",
    "3",
    "9",
    "10",
    "100",
    "1000",
    "1001",
    "1e6",
    "99999999999999999999",
    "-99999999999999999999",
    "0x10",
    "1_000",
    "½",
    "١٢",
    "+5",
    "--1",
    "1e",
    ".",
    "",
    " ",
    "   7   ",
    "true",
    "None",
    "palm",
    "PALM",
    "disc4",
    "ellipse",
    "'3'",
    '"3"',
    "1,5",
    "3600",
    "-3600",
    "2.9999999",
    "3.0",
    "0.000001",
    "1e-300",
]


def _all_keys() -> list[str]:
    keys = [s.key for s in TOP_KEYS] + ["Name", "Species", "name"]
    for s in LEVEL_KEYS:
        keys += [f"{n}{s.key}" for n in (0, 1, 2, 3, MAX_LEVELS, MAX_LEVELS + 1)]
    keys += [f"1{a}" for a in LEVEL_ALIASES] + [
        "DownAngle",
        "99Branches",
        "0",
        "-1Curve",
        "1e3Length",
        "Levles",
        "",
        "=",
        "#",
    ]
    return keys


KEYS = _all_keys()
value_st = st.one_of(
    st.sampled_from(NASTY_VALUES),
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.integers(-(10**30), 10**30).map(str),
    st.text(max_size=12),
)


def _check_parsed(p: Params) -> None:
    """A file that parses gives finite numbers only, and survives the writer and re-reading."""
    for name, v in vars(p).items():
        if isinstance(v, (int, float)) and not isinstance(v, bool):
            assert math.isfinite(v), name
    for lp in p.level:
        assert all(math.isfinite(v) for v in vars(lp).values())
    assert parse_params_text(format_params_text(p)) == p


def only_treegen_errors(data: bytes, source: str = "fuzz.txt") -> None:
    try:
        p = parse_params_bytes(data, source)
    except TreegenError as exc:
        msg = str(exc)
        assert msg.startswith(source) and msg.isprintable() and len(msg) < 600, msg
        return
    _check_parsed(p)


# ----------------------------------------------------------------------------- text format

# Strategies are built once (hypothesis validates a strategy on first use; rebuilding them
# inside a composite costs more than the parser being tested).
KEY_ST = st.sampled_from(KEYS)
BLANK_ST = st.sampled_from(["", "   ", "# comment", "\t# x = 1", "\r"])
SEP_ST = st.sampled_from([" ", "\t", " = ", "=", "  =  ", " == ", ": "])
TAIL_ST = st.sampled_from(["", "", " # note", "#", " extra", "\r"])
LINE_ST = st.one_of(
    BLANK_ST,
    st.tuples(st.one_of(KEY_ST, KEY_ST, KEY_ST, st.text(max_size=8)), SEP_ST, value_st, TAIL_ST).map("".join),
)


@st.composite
def text_files(draw):
    """Species text files built line by line from real keys (and near misses) and nasty values,
    with both `Key value` and `Key = value` syntax, comments, blank lines and odd line ends."""
    lines = draw(st.lists(LINE_ST, max_size=14))
    text = draw(st.sampled_from(["\n", "\r\n", "\n\n"])).join(lines)
    enc = draw(st.sampled_from(["utf-8", "utf-8-sig", "latin-1", "utf-16"]))
    return text.encode(enc, "replace")


@settings(max_examples=1500, **FUZZ)
@given(text_files())
def test_structured_text_files_raise_only_treegen_error(data):
    only_treegen_errors(data)


@settings(max_examples=300, **FUZZ)
@given(st.binary(max_size=300))
def test_random_bytes_raise_only_treegen_error(data):
    only_treegen_errors(data)


@settings(max_examples=300, **FUZZ)
@given(st.text(max_size=200))
def test_random_text_raises_only_treegen_error(text):
    only_treegen_errors(text.encode("utf-8", "surrogatepass"))


# ----------------------------------------------------------------------------- Arbaro XML

_PARAM = re.compile(r"""<param\s+name=['"]([^'"]*)['"]\s+value=['"]([^'"]*)['"]\s*/>""")
BASES = [p.read_text() for p in ARBARO]


def _xml_attr(text: str) -> str:
    """Quote text as an XML attribute value the way a careless tool might (or might not)."""
    return text.replace("&", "&amp;").replace("'", "&apos;").replace("<", "&lt;")


@st.composite
def xml_files(draw):
    """A real Arbaro file with structure-aware mutations: params dropped, duplicated, renamed,
    given nasty values or broken attributes; tags broken; species/root altered; DOCTYPE, entity
    references, encodings and random bytes spliced in."""
    text = draw(st.sampled_from(BASES))
    params = _PARAM.findall(text)
    assert params, "fixture without params"
    head, tail = text.split("<param", 1)[0], "\n  </species>\n</arbaro>\n"
    items = [f"<param name='{n}' value='{v}'/>" for n, v in params]
    for _ in range(draw(st.integers(1, 5))):
        i = draw(st.integers(0, len(items) - 1)) if items else 0
        n, v = params[i % len(params)]
        op = draw(st.integers(0, 17))
        if not items:
            items.append("<param name='Levels' value='2'/>")
        elif op == 0:
            del items[i]
        elif op == 1:
            items.insert(draw(st.integers(0, len(items))), items[i])
        elif op in (2, 3, 4):
            items[i] = f"<param name='{n}' value='{_xml_attr(draw(value_st))}'/>"
        elif op == 5:
            items[i] = f"<param name='{_xml_attr(draw(st.sampled_from(KEYS)))}' value='{v}'/>"
        elif op == 6:
            items[i] = draw(
                st.sampled_from(
                    [
                        f"<param value='{v}'/>",
                        f"<param name='{n}'/>",
                        "<param/>",
                        f"<param name='{n}' value='{v}' value='1'/>",
                        f"<param name='{n}' value=\"{v}'/>",
                        f"<param name={n} value={v}/>",
                        f"<param name='{n}' value='{v}' extra='x'/>",
                        f"<param name='{n}' value='&#0;'/>",
                        f"<param name='{n}' value='&#x1F;'/>",
                        f"<param name='{n}' value='&undefined;'/>",
                        f"<param name='{n}' value='1&#10;2'/>",
                    ]
                )
            )
        elif op == 7:  # break the tag
            s = items[i]
            j = draw(st.integers(0, len(s)))
            items[i] = (
                s[:j]
                + draw(st.sampled_from(["", "<", ">", "/>", "'", '"', "&", "<!--"]))
                + s[j + draw(st.integers(0, 3)) :]
            )
        elif op == 8:
            items[i] = f"<param name='{n}' value='{v}'>" + draw(
                st.sampled_from(["</param>", "<param name='Levels' value='1'/></param>", "", "<species/>"])
            )
        elif op == 9:
            items.insert(
                i,
                draw(
                    st.sampled_from(
                        [
                            "<species name='two'>",
                            "</species>",
                            "<arbaro>",
                            "<species>",
                            "<![CDATA[ Levels 3 ]]>",
                            "<?pi stuff?>",
                            "<!-- -- -->",
                            "text & more",
                        ]
                    )
                ),
            )
        elif op == 10:
            head = draw(
                st.sampled_from(
                    [
                        "<?xml version='1.0' encoding='utf-16'?>\n<arbaro><species name='x'>",
                        "<?xml version='1.0' encoding='bogus-enc'?>\n<arbaro><species name='x'>",
                        "<?xml version='1.0' encoding='latin-1'?>\n<arbaro><species name='caf\u00e9'>",
                        "<!DOCTYPE a [<!ENTITY e 'x'>]>\n<arbaro><species name='x'>",
                        "<!DOCTYPE arbaro SYSTEM 'http://example.invalid/a.dtd'>\n<arbaro><species>",
                        "<tree><species name='x'>",
                        "<arbaro><species name=''>",
                        "<arbaro><species name='a#b'>",
                        "<arbaro><species name='a\tb'>",
                        "<arbaro><species name='&#10;'>",
                        "\ufeff<arbaro><species name='bom'>",
                        "<arbaro><species name='x' name='y'>",
                        "<arbaro>\n<species name='x'>",
                        "<?xml version='2.0'?><arbaro><species name='x'>",
                    ]
                )
            )
        elif op == 11:
            tail = draw(
                st.sampled_from(
                    [
                        "",
                        "</species>",
                        "</arbaro>",
                        "</species></arbaro><x/>",
                        "</species></arbaro>\x00",
                        "</species>\n</tree>",
                        "</species><species name='b'></species></arbaro>",
                    ]
                )
            )
        elif op == 12:
            s = items[i]
            j = draw(st.integers(0, len(s)))
            items[i] = s[:j] + draw(st.binary(max_size=8)).decode("latin-1") + s[j:]
        elif op == 13:  # a level key far beyond Levels
            items.append(
                f"<param name='{draw(st.integers(0, 12))}{draw(st.sampled_from([k.key for k in LEVEL_KEYS]))}' "
                f"value='{_xml_attr(draw(value_st))}'/>"
            )
        elif op == 14:
            items[i] = (
                f"<param name='Levels' value='{draw(st.sampled_from(['0', '1', '9', '10', '-1', '3.5']))}'/>"
            )
        else:  # several nasty values at once
            for k in draw(st.lists(st.integers(0, len(items) - 1), max_size=4)):
                n2, _ = params[k % len(params)]
                items[k] = f"<param name='{n2}' value='{_xml_attr(draw(value_st))}'/>"
    text = head + "\n    ".join(items) + tail
    enc = draw(st.sampled_from(["utf-8", "utf-8", "latin-1", "utf-16"]))
    return text.encode(enc, "replace")


@settings(max_examples=1500, **FUZZ)
@given(xml_files())
def test_mutated_arbaro_files_raise_only_treegen_error(data):
    only_treegen_errors(data, "fuzz.xml")


@pytest.mark.parametrize("decl", ["bogus-enc", "utf-99", "x" * 300])
def test_unknown_xml_encoding_is_a_user_error(decl):
    # Regression (found by this fuzzer): expat raised LookupError for unknown encodings.
    data = f"<?xml version='1.0' encoding='{decl}'?><arbaro><species name='x'/></arbaro>".encode()
    with pytest.raises(TreegenError, match="unreadable XML"):
        parse_params_bytes(data, "enc.xml")


def test_unmutated_arbaro_fixtures_parse():
    # The mutation base itself is valid, so mutations explore the edge of the valid region.
    for path in ARBARO:
        _check_parsed(parse_params_bytes(path.read_bytes(), str(path)))


# ----------------------------------------------------------------------------- layouts

import treegen_cli.forest as forest  # noqa: E402

LAYOUT_DIR = Path(tempfile.mkdtemp(prefix="treegen-fuzz-"))
for _name in ("quaking_aspen.txt", "palm.txt"):
    shutil.copy(ROOT / "species" / _name, LAYOUT_DIR / _name)

BASE_LAYOUT = {
    "name": "fuzz",
    "camera": {"position": [0, -40, 2], "target": [0, 0, 5], "fov_deg": 60, "width_px": 1920},
    "wind": {
        "speed": 4,
        "direction_deg": 30,
        "gust": 0.3,
        "turbulence": 0.3,
        "duration": 2,
        "fps": 10,
        "seed": 1,
        "phase_jitter": 0.2,
        "enabled": True,
    },
    "defaults": {
        "seed": 0,
        "scale": 1,
        "rotation_deg": 0,
        "max_joints": 16,
        "lod_distances": [10, 40],
        "error_px": 1,
        "phase_variants": 2,
    },
    "instances": [
        {"species": "quaking_aspen.txt", "position": [0, 0], "seed": 2, "rotation_deg": 10, "scale": 1.1},
        {"species": "palm.txt", "position": [5, 2, 0.5]},
    ],
    "scatter": [
        {
            "species": [{"file": "quaking_aspen.txt", "weight": 2}, {"file": "palm.txt"}],
            "rectangle": {"min": [-20, -20], "max": [20, 20]},
            "count": 6,
            "min_spacing": 2,
            "seed": 3,
            "variants": 2,
            "z": 0,
            "scale": [0.8, 1.2],
            "rotation_deg": [0, 360],
        },
        {"species": [{"file": "palm.txt"}], "polygon": [[0, 0], [10, 0], [10, 10], [0, 10]], "density": 0.05},
    ],
}

JSON_NASTY = [
    float("nan"),
    float("inf"),
    -float("inf"),
    1e308,
    -1e308,
    5e-324,
    0,
    -0.0,
    -1,
    1,
    0.5,
    10**400,
    -(10**400),
    2**63,
    100001,
    1e6,
    "",
    "x",
    "../../etc/passwd",
    "/",
    "palm.txt",
    "nope.txt",
    None,
    True,
    False,
    [],
    [0],
    [0, 0],
    [1, 2, 3, 4],
    [[0, 0], [0, 0], [0, 0]],
    [[0, 0], [1e308, 0], [0, 1e308]],
    {},
    {"min": [0, 0]},
    {"min": [-1e308, -1e308], "max": [1e308, 1e308]},
    [float("nan"), 0, 0],
]


NASTY_ST = st.sampled_from(JSON_NASTY)  # drawn values are deep-copied before use
EXTRA_KEY_ST = st.sampled_from(
    ["extra", "count", "density", "polygon", "rectangle", "lod_distances", "species", ""]
)
JSON_VALUES = st.recursive(
    st.none() | st.booleans() | st.integers(-(10**20), 10**20) | st.floats() | st.text(max_size=6),
    lambda ch: st.lists(ch, max_size=4) | st.dictionaries(st.text(max_size=6), ch, max_size=3),
    max_leaves=8,
)


def _paths(value, prefix=()):
    """Every (path, value) in a JSON tree, containers included."""
    yield prefix, value
    if isinstance(value, dict):
        for k, v in value.items():
            yield from _paths(v, prefix + (k,))
    elif isinstance(value, list):
        for i, v in enumerate(value):
            yield from _paths(v, prefix + (i,))


def _set(tree, path, value):
    if not path:
        return value
    node = tree
    for k in path[:-1]:
        node = node[k]
    node[path[-1]] = value
    return tree


@st.composite
def layouts(draw):
    """The base layout with 1–4 tree mutations: a node replaced by a nasty value or a random
    JSON value, deleted, duplicated into a list, or given an unknown sibling key."""
    tree = json.loads(json.dumps(BASE_LAYOUT))
    for _ in range(draw(st.integers(1, 4))):
        paths = [p for p, _ in _paths(tree)]
        path = draw(st.sampled_from(paths))
        op = draw(st.integers(0, 5))
        if op <= 1:
            tree = _set(tree, path, copy.deepcopy(draw(NASTY_ST)))
        elif op == 2:
            tree = _set(tree, path, draw(JSON_VALUES))
        elif op == 3 and path:
            parent = tree
            for k in path[:-1]:
                parent = parent[k]
            del parent[path[-1]]
        elif op == 4:
            node = tree
            for k in path:
                node = node[k]
            if isinstance(node, dict):
                node[draw(EXTRA_KEY_ST)] = copy.deepcopy(draw(NASTY_ST))
        else:
            node = tree
            for k in path:
                node = node[k]
            tree = _set(tree, path, [node, copy.deepcopy(node)])
    return tree


def _layout_only_treegen_errors(text: str) -> None:
    path = LAYOUT_DIR / "layout.json"
    path.write_text(text, "utf-8", errors="surrogatepass")
    try:
        layout = forest.load_layout(path)
    except TreegenError as exc:
        msg = str(exc)
        assert msg.startswith(str(path)) and len(msg) < 2000, msg
        return
    assert layout.placements
    for pl in layout.placements:
        assert all(math.isfinite(c) for c in pl.position) and pl.scale > 0


@settings(max_examples=1200, **FUZZ)
@given(layouts())
def test_mutated_layouts_raise_only_treegen_error(tree):
    _layout_only_treegen_errors(json.dumps(tree, allow_nan=True))


@settings(max_examples=300, **FUZZ)
@given(
    st.one_of(
        st.text(max_size=120),
        st.binary(max_size=120).map(lambda b: b.decode("latin-1")),
        st.sampled_from(
            [
                "",
                "{",
                "[]",
                "null",
                "1",
                '"x"',
                "NaN",
                "{}",
                '{"camera": 1}',
                '{"camera": {"position": [0,0,0], "target": [0,0,0]}}',
            ]
        ),
    )
)
def test_random_layout_text_raises_only_treegen_error(text):
    _layout_only_treegen_errors(text)


@pytest.mark.parametrize(
    "patch",
    [
        {"instances": [{"species": "palm.txt", "position": [10**400, 0]}]},  # int > float
        {
            "scatter": [
                {
                    "species": [{"file": "palm.txt"}],
                    "density": 10,
                    "rectangle": {"min": [-1e308, -1e308], "max": [1e308, 1e308]},
                }
            ]
        },  # inf area
        {
            "scatter": [
                {
                    "species": [{"file": "palm.txt"}],
                    "count": 5,
                    "min_spacing": 1e308,
                    "rectangle": {"min": [0, 0], "max": [1, 1]},
                }
            ]
        },  # inf spacing²
        {
            "scatter": [{"species": [{"file": "palm.txt"}], "count": 3, "polygon": [[0, 0], [0, 0], [0, 0]]}]
        },  # zero area
    ],
)
def test_layout_regressions_found_by_fuzzing(patch):
    _layout_only_treegen_errors(json.dumps({**BASE_LAYOUT, **patch}))


def test_base_layout_is_valid():
    _layout_only_treegen_errors(json.dumps(BASE_LAYOUT))
    layout = forest.load_layout(LAYOUT_DIR / "layout.json")
    assert len(layout.placements) == 2 + 6 + 5  # instances + count + density · area


# ----------------------------------------------------------------------------- the CLI

NASTY_FILES = {
    "binary.txt": bytes(range(256)) * 4,
    "nan.txt": b"Levels 2\nScale nan\n",
    "huge.xml": b"<arbaro><species name='x'><param name='Scale' value='1e999'/></species></arbaro>",
    "entity.xml": b"<!DOCTYPE a [<!ENTITY e 'x'>]><arbaro><species/></arbaro>",
    "broken.xml": b"<arbaro><species name='x'><param name='Levels' value='2'",
    "utf16.txt": "Levels 2\nScale 3\n\u00e9\n".encode("utf-16"),
    "empty.txt": b"",
}


def _run(*args):
    return subprocess.run(
        [sys.executable, "-m", "treegen_cli", *map(str, args)], capture_output=True, text=True, cwd=ROOT
    )


@pytest.mark.parametrize("name", sorted(NASTY_FILES))
def test_cli_nasty_species_files_exit_2_without_traceback(tmp_path, name):
    path = tmp_path / name
    path.write_bytes(NASTY_FILES[name])
    proc = _run("make", path, "-o", tmp_path / "out.glb", "--no-wind")
    assert proc.returncode == 2, (proc.stdout, proc.stderr)
    assert "Traceback" not in proc.stderr and proc.stdout == ""
    assert len(proc.stderr.strip().splitlines()) == 1 and name in proc.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == [name]


def test_cli_nasty_layout_exits_2_without_traceback(tmp_path):
    for i, text in enumerate(
        [
            '{"camera": {"position": [0, 0, 1e999], "target": [0, 0, 0]}}',
            '{"camera": \x00}',
            json.dumps({**BASE_LAYOUT, "instances": 3}),
        ]
    ):
        path = tmp_path / f"bad{i}.json"
        path.write_text(text)
        proc = _run("forest", path, "-o", tmp_path / "forest.glb")
        assert proc.returncode == 2, proc.stderr
        assert "Traceback" not in proc.stderr and f"bad{i}.json" in proc.stderr
    assert not (tmp_path / "forest.glb").exists()

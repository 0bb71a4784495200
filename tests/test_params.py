"""Species files: readers, validation, defaults, writer round trip, and the bundled library."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from treegen_cli.errors import TreegenError
from treegen_cli.params import (
    LEAF_SHAPES,
    LEVEL_KEYS,
    LEVEL_SLOTS,
    TOP_KEYS,
    LevelParams,
    Params,
    arbaro_level_defaults,
    default_params,
    format_params_text,
    load_params,
    params_dict,
    parse_params_bytes,
    parse_params_text,
    parse_params_xml,
)

ROOT = Path(__file__).resolve().parents[1]
SPECIES = sorted((ROOT / "species").glob("*.txt"))
FIXTURES = ROOT / "tests" / "fixtures"
ARBARO = sorted((FIXTURES / "arbaro").glob("*.xml"))


def fragment(text: str, source: str = "<string>"):
    """A few keys over the defaults: the text reader with `partial` (a species file must list
    every parameter; these tests are about the syntax, not the file)."""
    return parse_params_text(text, source, partial=True)


def expect_error(text: str, *parts: str, source: str = "sp/x.txt") -> str:
    """Parse `text` (bytes dispatch, as load_params does); the error must name every part."""
    data = text.encode() if isinstance(text, str) else text
    with pytest.raises(TreegenError) as info:
        parse_params_bytes(data, source)
    msg = str(info.value)
    assert "\n" not in msg
    for part in parts:
        assert part in msg, f"{part!r} not in {msg!r}"
    return msg


# ------------------------------------------------------------------------------ library


def test_library_has_the_required_species():
    names = {p.stem for p in SPECIES}
    required = {
        "quaking_aspen",
        "black_tupelo",
        "weeping_willow",
        "ca_black_oak",
        "sassafras",
        "lombardy_poplar",
        "palm",
        "fan_palm",
        "european_larch",
        "tamarack",
        "eastern_cottonwood",
        "desert_bush",
        "balsam_fir",
    }
    assert required <= names
    assert len(names) >= 14


@pytest.mark.parametrize("path", SPECIES, ids=lambda p: p.stem)
def test_every_species_file_loads_and_states_its_source(path):
    p = load_params(path)
    assert p.name == path.stem
    assert len(p.level) == LEVEL_SLOTS
    head = path.read_text().splitlines()[:3]
    assert all(line.startswith("#") for line in head)
    assert "source" in path.read_text().lower()
    hash(p)  # immutable and hashable


def test_paper_values_land_in_the_right_fields():
    aspen = load_params(ROOT / "species/quaking_aspen.txt")
    assert (aspen.shape, aspen.levels, aspen.scale, aspen.scale_v) == (7, 3, 13.0, 3.0)
    assert aspen.scale0_v == 0.0  # paper, not Arbaro's 0.2
    assert [aspen.level[n].curve_res for n in range(4)] == [3, 5, 3, 1]
    assert aspen.level[1].down_angle_v == -50.0
    assert aspen.level[3].rotate == 77.0
    willow = load_params(ROOT / "species/weeping_willow.txt")
    assert willow.level[3].branches == 300.0
    assert (willow.leaves, willow.attraction_up, willow.prune_ratio) == (15.0, -3.0, 1.0)
    assert willow.level[1].rotate == -120.0
    oak = load_params(ROOT / "species/ca_black_oak.txt")
    assert oak.level[2].curve_v == -30.0  # the helix
    assert (oak.base_splits, oak.level[0].seg_splits, oak.flare) == (2, 0.4, 1.2)


@pytest.mark.parametrize("path", ARBARO, ids=lambda p: p.stem)
def test_every_arbaro_file_loads(path):
    p = load_params(path)
    assert p.name.replace("_", "-") == path.stem.replace("_", "-")
    assert isinstance(p.level[0].curve_res, int)


def test_arbaro_conversions_in_library_equal_their_xml():
    pairs = {
        "sassafras": "sassafras",
        "fan_palm": "fanpalm",
        "tamarack": "tamarack",
        "european_larch": "european_larch",
        "desert_bush": "desert_bush",
        "black_tupelo": "black_tupelo",
    }  # tupelo: paper == Arbaro
    for txt, xml in pairs.items():
        a = load_params(ROOT / f"species/{txt}.txt")
        b = load_params(FIXTURES / f"arbaro/{xml}.xml")
        assert a == dataclasses.replace(b, name=a.name), txt


# ------------------------------------------------------------------------------ formats


@pytest.mark.parametrize("stem", ["pair_willow", "pair_small"])
def test_xml_and_text_with_same_values_give_identical_params(stem):
    xml_path = FIXTURES / ("arbaro/weeping_willow.xml" if stem == "pair_willow" else f"{stem}.xml")
    a = load_params(xml_path)
    b = load_params(FIXTURES / f"{stem}.txt")
    assert a == b
    assert hash(a) == hash(b)


def test_pair_small_values():
    p = load_params(FIXTURES / "pair_small.txt")
    assert p.leaf_shape == LEAF_SHAPES["palm"] == 6
    assert p.level[1].branches == 12.5 and p.leaves == -6.0
    assert p.level[2].rotate == -120.0  # index == Levels: the leaves' level


def test_seed_paper_spellings_map_to_weber_penn_keys():
    seed = fragment(
        "0CurveResolution 5\n0Curve 10\n1Branches 20\n1BranchLength 0.4\n"
        "1AngleDown 50\n1AngleRotate 140\n1CurveResolution 4\n"
    )
    wp = fragment(
        "0CurveRes 5\n0Curve 10\n1Branches 20\n1Length 0.4\n1DownAngle 50\n1Rotate 140\n1CurveRes 4\n"
    )
    assert seed == wp
    assert (
        seed.level[0].curve_res,
        seed.level[1].length,
        seed.level[1].down_angle,
        seed.level[1].rotate,
        seed.level[1].curve_res,
    ) == (5, 0.4, 50.0, 140.0, 4)


def test_text_syntax_variants():
    a = fragment("Levels 2\nScale = 3\n  Ratio\t0.02   # trailing comment\n\n# c\n")
    b = fragment("levels=2\nSCALE 3\nratio = 0.02")
    assert a == b
    assert (a.levels, a.scale, a.ratio) == (2, 3.0, 0.02)
    assert fragment("Species my oak tree\nLevels 1").name == "my oak tree"
    assert fragment("Levels 1", source="dir/holly.txt").name == "holly"


def test_leaf_shape_names():
    for name, code in LEAF_SHAPES.items():
        assert fragment(f"LeafShape {name}").leaf_shape == code
        assert fragment(f"LeafShape {name.upper()}").leaf_shape == code
    assert fragment("LeafShape 3").leaf_shape == 3


def test_utf8_bom_and_xml_with_leading_whitespace():
    assert parse_params_bytes("\ufeffLevels 2\n".encode(), partial=True).levels == 2
    xml = "\n  <arbaro><species name='t'><param name='Levels' value='1'/></species></arbaro>"
    assert parse_params_bytes(xml.encode()).levels == 1


def test_other_encodings_and_line_ends_read_or_say_what_to_do():
    """Notepad's "Unicode" (UTF-16 with a byte-order mark) and classic Mac CR line ends read
    as the UTF-8 file does; UTF-16 without a mark says to save as UTF-8 (it read as binary
    data; CR alone as an empty file)."""
    text = "Levels 2\nScale = 3\nRatio 0.02\n"
    plain = parse_params_bytes(text.encode(), partial=True)
    assert parse_params_bytes(text.encode("utf-16"), partial=True) == plain
    assert parse_params_bytes(text.replace("\n", "\r").encode(), partial=True) == plain
    xml = "<arbaro><species name='t'><param name='Levels' value='1'/></species></arbaro>"
    assert parse_params_bytes(xml.encode("utf-16")).levels == 1
    expect_error(text.encode("utf-16-le"), "x.txt:1: UTF-16 text without a byte-order mark; save it as UTF-8")
    expect_error(text.encode("utf-16") + b"\x00", "x.txt: not valid UTF-16 text")  # (a traceback)
    expect_error(b"\xff\xfeS\x00c\x00\x00\xd8", "not valid UTF-16 text")
    expect_error(text.encode("utf-32"), "x.txt:1: UTF-32 text; save it as UTF-8")


@pytest.mark.parametrize(
    "line, parts",
    [
        ("Scale 13_0", ["Scale = '13_0' is not a number"]),  # float() took it as 130
        ("Scale \uff11\uff13", ["is not a number"]),  # full-width digits, read as 13
        ("1Curve \u221240", ["type the minus sign as '-'"]),  # pasted from a PDF
        ("Scale: 13", ["'Scale: 13': write Scale 13 or Scale = 13"]),  # was "did you mean Scale?"
        ("Scale inf", ["is not a finite number"]),
    ],
)
def test_numbers_are_ascii_as_arbaro_writes_them(line, parts):
    expect_error(f"Levels 2\n{line}\n", "x.txt:2: ", *parts)


def test_name_and_species_are_named_as_one_key_when_both_are_given():
    expect_error("Name oak\nLevels 2\nSpecies elm\n", "duplicate key Species (first set on line 1 as Name")


# ------------------------------------------------------------------------------ defaults


def test_defaults_apply_for_absent_keys_and_file_values_win():
    p = fragment("Levels 2\nScale 7\n1Branches 7\n")
    d = default_params("tree")
    assert p == dataclasses.replace(
        d,
        levels=2,
        scale=7.0,
        level=(d.level[0], dataclasses.replace(d.level[1], branches=7.0)) + d.level[2:],
    )
    # Arbaro's per-level defaults, level 3's repeated below
    assert d.level[0].length == 1.0 and d.level[1].length == 0.5
    assert [d.level[n].down_angle for n in range(4)] == [0.0, 30.0, 30.0, 30.0]
    assert d.level[9] == d.level[3] == arbaro_level_defaults(7)
    # dataclass top-level defaults are Arbaro's too
    assert all(
        getattr(d, f.name) == getattr(Params(), f.name)
        for f in dataclasses.fields(Params)
        if f.name not in ("level", "name")
    )


def test_levels_above_three_repeat_level_three_unless_given():
    p = fragment("Levels 5\n3DownAngle 33\n3Rotate -90\n5Rotate 77\n")
    assert p.level[4].down_angle == 33.0 and p.level[4].rotate == -90.0
    assert p.level[5].down_angle == 33.0 and p.level[5].rotate == 77.0
    assert p.level[6].rotate == 77.0


# ------------------------------------------------------------------------------ writer


def test_params_dict_is_canonical_and_json_ready():
    p = load_params(ROOT / "species/black_tupelo.txt")
    d = params_dict(p)
    assert d["Name"] == "black_tupelo" and d["Levels"] == 4
    assert set(s.key for s in TOP_KEYS) <= set(d)
    assert len(d) == 1 + len(TOP_KEYS) + (p.levels + 1) * len(LEVEL_KEYS)
    assert d["0Taper"] == 1.1 and d["2Curve"] == -10.0
    json.dumps(d)


@pytest.mark.parametrize("path", SPECIES + ARBARO, ids=lambda p: p.name)
def test_round_trip_through_text(path):
    p = load_params(path)
    text = format_params_text(p, header=f"round trip of {path.name}")
    assert parse_params_text(text) == p


# ------------------------------------------------------------------------------ colours


def test_leaf_and_bark_colour_are_srgb_hex_stored_linear():
    p = fragment("LeafColor 5a7a2e\nBarkColor = FFFFFF\n")
    assert p.bark_color == (1.0, 1.0, 1.0)
    # 0x5a = 90 → ((90/255 + 0.055) / 1.055)^2.4, the sRGB curve
    assert p.leaf_color[0] == pytest.approx(((90 / 255 + 0.055) / 1.055) ** 2.4)
    assert default_params().leaf_color is None and default_params().bark_color is None
    d = params_dict(p)
    assert (d["LeafColor"], d["BarkColor"]) == ("5a7a2e", "ffffff")
    assert params_dict(default_params())["LeafColor"] is None
    json.dumps(d)


def test_colour_round_trips_through_the_writer_for_every_byte():
    for b in range(256):
        p = fragment(f"LeafColor {b:02x}{255 - b:02x}{b // 2:02x}")
        text = format_params_text(p)
        assert f"{b:02x}{255 - b:02x}{b // 2:02x}" in text
        assert parse_params_text(text) == p
    assert "LeafColor" not in format_params_text(default_params())


def test_colour_in_arbaro_xml_may_keep_its_hash():
    xml = (
        '<arbaro><species name="x"><param name="LeafColor" value="#5a7a2e"/>'
        '<param name="BarkColor" value="30201a"/></species></arbaro>'
    )
    p = parse_params_xml(xml)
    assert p.leaf_color == fragment("LeafColor 5a7a2e").leaf_color
    assert params_dict(p)["BarkColor"] == "30201a"


@pytest.mark.parametrize(
    "value, parts",
    [
        ("#5a7a2e", ["LeafColor has no value", "6 hex digits", "'#'"]),  # '#' starts a comment
        ("5a7a2", ["LeafColor = '5a7a2' is not a colour", "6 hex digits"]),
        ("green", ["'green' is not a colour", "e.g. 5a7a2e"]),
        ("5a7a2e00", ["is not a colour"]),
        ("0x5a7a2e", ["is not a colour"]),
    ],
)
def test_colour_errors_are_one_line_naming_file_line_and_key(value, parts):
    expect_error(f"Levels 2\nLeafColor {value}\n", "sp/x.txt:2:", *parts)


def test_colour_errors_in_xml_and_duplicates():
    expect_error(
        '<arbaro><species name="x">\n<param name="BarkColor" value="brown"/></species></arbaro>',
        "sp/x.txt:2:",
        "BarkColor",
        "not a colour",
    )
    expect_error("LeafColor 5a7a2e\nleafcolor 5a7a2e\n", ":2:", "duplicate key leafcolor")
    expect_error("LeafColour 5a7a2e\n", "unknown key LeafColour", "did you mean LeafColor?")


# ------------------------------------------------------------------------------ errors


def test_error_out_of_range_names_file_line_key_range():
    msg = expect_error("Levels 3\n# c\n1DownAngle = 400\n", "sp/x.txt:3:", "1DownAngle", "400", "[-180, 180]")
    assert msg == "sp/x.txt:3: 1DownAngle = 400 is out of range [-180, 180]"


@pytest.mark.parametrize(
    "text, parts",
    [
        ("Shape 9", ["sp/x.txt:1:", "Shape", "[0, 8]"]),
        ("Scale 0", ["Scale", "(0, inf)"]),
        ("LeafQuality 1.5", ["LeafQuality", "(0, 1]"]),
        ("0Taper 3", ["0Taper", "[0, 3)"]),
        ("Levels 10", ["Levels", "[0, 9]"]),
        ("Levels 3\n2CurveRes 0", [":2:", "2CurveRes", "[1, 100]"]),
        ("Levels 2.5", ["Levels", "whole number", "[0, 9]"]),
        ("Scale inf", ["Scale", "finite"]),
        ("Scale nan", ["Scale", "finite"]),
    ],
)
def test_error_out_of_range(text, parts):
    expect_error(text, *parts)


def test_error_non_numeric_value():
    expect_error("Levels 3\nRatio = abc", "sp/x.txt:2:", "Ratio", "not a number", "(0, inf)")
    expect_error("LeafShape maple", ":1:", "LeafShape", "palm")
    expect_error("Levels 3 4", ":1:", "Levels", "one value")
    expect_error("Levels", ":1:", "Levels", "no value", "[0, 9]")


@pytest.mark.parametrize(
    "key, suggestion",
    [
        ("1DownAngel", "1DownAngle"),
        ("Brnaches", None),
        ("LeafScal", "LeafScale"),
        ("AtractionUp", "AttractionUp"),
        ("2CurveRess", "2CurveRes"),
        ("PruneWidthPeek", "PruneWidthPeak"),
    ],
)
def test_error_unknown_key_suggests_the_right_name(key, suggestion):
    msg = expect_error(f"Levels 3\n{key} 1\n", "sp/x.txt:2:", "unknown key", key)
    if suggestion:
        assert f"did you mean {suggestion}?" in msg


def test_error_level_key_without_digit():
    expect_error("DownAngle 30", ":1:", "DownAngle", "level digit", "1DownAngle")


def test_error_level_index_beyond_levels():
    expect_error("Levels 2\n3DownAngle 30\n", "sp/x.txt:2:", "3DownAngle", "Levels = 2")
    # Levels given after the key still counts; index == Levels is fine
    expect_error("4Length 1\nLevels 3\n", ":1:", "4Length", "Levels = 3")
    assert fragment("3Rotate 20\nLevels 3").level[3].rotate == 20.0
    expect_error("12Length 1", ":1:", "12Length", "9")


def test_error_duplicate_key_names_both_lines():
    expect_error("Levels 3\nScale 3\n\nScale 4\n", "sp/x.txt:4:", "Scale", "line 2")
    expect_error("1Length 0.3\n1BranchLength 0.3\n", ":2:", "1BranchLength", "1Length", "line 1")
    expect_error("Name a\nSpecies b\n", ":2:", "Species", "line 1")


def test_error_bad_names():
    expect_error("Name\nLevels 2", ":1:", "Name")
    expect_error("<arbaro><species name='oak #2'/></arbaro>", ":1:", "species name", "'#'")


def test_error_empty_and_binary_files():
    expect_error("", "sp/x.txt:1:", "empty")
    expect_error("  \n# only comments\n\n", "sp/x.txt:1:", "empty")
    expect_error(b"Levels 3\nScale\x00 4\n", "sp/x.txt:2:", "binary")
    expect_error(b"Levels 3\n\n\xff\xfe\x80junk", "sp/x.txt:3:", "UTF-8")
    expect_error(bytes(range(256)), "sp/x.txt:1:", "binary")


def test_error_malformed_xml_has_line_and_column():
    msg = expect_error(
        "<arbaro>\n  <species name='a'>\n    <param name='Levels' value='2'>\n  </species>\n</arbaro>\n",
        "sp/x.txt:4:",
        "malformed XML",
        source="sp/x.txt",
    )
    assert msg.startswith("sp/x.txt:4:")
    expect_error("<arbaro><species", "malformed XML")


def test_xml_errors_name_the_param_line():
    xml = (
        "<arbaro>\n<species name='t'>\n<param name='Levels' value='2'/>\n"
        "<param name='1DownAngle' value='400'/>\n</species>\n</arbaro>\n"
    )
    assert expect_error(xml, source="t.xml") == "t.xml:4: 1DownAngle = 400 is out of range [-180, 180]"
    xml = (
        "<arbaro><species name='t'>\n<param name='Levels' value='2'/>\n"
        "<param name='1DownAngel' value='40'/>\n</species></arbaro>"
    )
    expect_error(xml, "t.xml:3:", "1DownAngel", "did you mean 1DownAngle?", source="t.xml")
    xml = (
        "<arbaro><species>\n<param name='Levels' value='2'/>\n"
        "<param name='3Length' value='1'/></species></arbaro>"
    )
    expect_error(xml, "t.xml:3:", "3Length", "Levels = 2", source="t.xml")
    xml = "<arbaro><species>\n<param name='Scale' value='1'/>\n<param name='Scale' value='2'/></species></arbaro>"
    expect_error(xml, "t.xml:3:", "Scale", "line 2", source="t.xml")
    expect_error("<arbaro><species><param name='Scale'/></species></arbaro>", "Scale", "value=")
    expect_error("<trees/>", "<trees>", "arbaro")
    expect_error("<arbaro/>", "no <species>")
    expect_error("<arbaro><species name='a'/><species name='b'/></arbaro>", "one species")


def test_xml_entity_declarations_are_refused():
    bomb = (
        '<?xml version="1.0"?>\n<!DOCTYPE lolz [<!ENTITY lol "lol">'
        '<!ENTITY lol2 "&lol;&lol;&lol;&lol;">]>\n'
        '<arbaro><species name="&lol2;"/></arbaro>'
    )
    expect_error(bomb, "sp/x.txt:2:", "DOCTYPE")
    ext = (
        '<?xml version="1.0"?>\n<!DOCTYPE a SYSTEM "file:///etc/passwd">\n'
        '<arbaro><species name="a"/></arbaro>'
    )
    expect_error(ext, "DOCTYPE")
    with pytest.raises(TreegenError):
        parse_params_xml(bomb, "b.xml")


def test_error_messages_escape_control_characters_and_stay_short():
    msg = expect_error("Lev\x1bels 3", ":1:", "Lev\\x1bels")
    assert msg.isprintable()
    msg = expect_error("Scale " + "9" * 5000, ":1:", "Scale", "(0, inf)")
    assert len(msg) < 200
    # line numbers count "\n" only, like editors, even with a form feed in a comment
    expect_error("Levels 3  # a\fb\nScale 2\n1DownAngle 400", "sp/x.txt:3:", "1DownAngle")


def test_error_missing_file_and_directory(tmp_path):
    with pytest.raises(TreegenError, match="no such species file"):
        load_params(tmp_path / "nope.txt")
    with pytest.raises(TreegenError, match="is a directory"):
        load_params(tmp_path)


def test_load_params_dispatches_on_content_not_suffix(tmp_path):
    f = tmp_path / "looks_like_text.txt"
    f.write_text((FIXTURES / "pair_small.xml").read_text())
    assert load_params(f) == load_params(FIXTURES / "pair_small.txt")


# ------------------------------------------------------------------------------ fuzzing

BASE_TEXTS = [
    (ROOT / "species" / n).read_text()
    for n in ("quaking_aspen.txt", "weeping_willow.txt", "fan_palm.txt", "balsam_fir.txt")
]
BASE_XML = [(FIXTURES / "arbaro" / n).read_text() for n in ("quaking_aspen.xml", "fanpalm.xml")]
JUNK = st.sampled_from(
    [
        "=",
        "#",
        " ",
        "\t",
        "-",
        "e",
        "9",
        ".",
        "nan",
        "1e999",
        "<",
        ">",
        "&",
        "'",
        '"',
        "/>",
        "\x00",
        "\u00e9",
        "Levels",
        "1",
        "0x10",
        "Name",
        "==",
    ]
)


@st.composite
def mutated(draw, bases):
    """A real species file with a few line-level mutations."""
    lines = draw(st.sampled_from(bases)).splitlines()
    for _ in range(draw(st.integers(1, 4))):
        i = draw(st.integers(0, len(lines) - 1))
        line = lines[i]
        op = draw(st.sampled_from(["drop", "swap", "junk", "bytes", "dup", "del", "text"]))
        if op == "drop" and line:
            j = draw(st.integers(0, len(line) - 1))
            k = draw(st.integers(j + 1, min(len(line), j + 4)))
            lines[i] = line[:j] + line[k:]
        elif op == "swap":
            toks = line.split()
            if len(toks) >= 2:
                a, b = draw(st.permutations(range(len(toks))))[:2]
                toks[a], toks[b] = toks[b], toks[a]
                lines[i] = " ".join(toks)
        elif op == "junk":
            j = draw(st.integers(0, len(line)))
            lines[i] = line[:j] + draw(JUNK) + line[j:]
        elif op == "bytes":
            lines[i] = draw(st.binary(max_size=12)).decode("latin-1")
        elif op == "dup":
            lines.insert(draw(st.integers(0, len(lines))), line)
        elif op == "del" and len(lines) > 1:
            del lines[i]
        elif op == "text":
            lines[i] = draw(st.text(max_size=20))
    raw = "\n".join(lines)
    if draw(st.booleans()):
        return raw.encode("utf-8", "surrogatepass")
    return raw.encode("latin-1", "replace")


def _only_treegen_errors(data: bytes):
    try:
        p = parse_params_bytes(data, "fuzz.txt")
    except TreegenError as exc:
        assert str(exc).isprintable() and str(exc).startswith("fuzz.txt")
        return
    # Whatever parses also survives the writer.
    assert parse_params_text(format_params_text(p)) == p


@settings(max_examples=300, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow])
@given(mutated(BASE_TEXTS))
def test_mutated_text_files_raise_only_treegen_error(data):
    _only_treegen_errors(data)


@settings(max_examples=150, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow])
@given(mutated(BASE_XML))
def test_mutated_xml_files_raise_only_treegen_error(data):
    _only_treegen_errors(data)


@settings(max_examples=100, deadline=None, derandomize=True)
@given(st.binary(max_size=200))
def test_random_bytes_raise_only_treegen_error(data):
    _only_treegen_errors(data)


def test_level_params_contract_unchanged():
    # The reader fills every LevelParams field from the key table and nothing else.
    assert {s.field for s in LEVEL_KEYS} == {f.name for f in dataclasses.fields(LevelParams)}
    assert {s.field for s in TOP_KEYS} == {f.name for f in dataclasses.fields(Params)} - {
        "name",
        "level",
        "key_lines",  # where each key was read, for later errors; not a parameter
    }


def test_a_name_holding_an_equals_sign_survives_the_writer():
    """Found by the fuzz test above: `Name==  fir` names the species '=  fir', which the writer
    wrote as `Name =  fir` and the reader then took for 'fir'."""
    for text in ("Name==   fir\nLevels 2\n", "Name = a=b\nLevels 2\n"):
        p = fragment(text)
        assert "=" in p.name and parse_params_text(format_params_text(p)) == p


# ------------------------------------------------------------------------------ completeness


def test_a_text_file_missing_parameters_is_refused_through_the_cli(tmp_path):
    """A name alone used to grow a leafless 45-stem default tree and exit 0."""
    from conftest import run_treegen

    (tmp_path / "nameonly.txt").write_text("Name my_oak\n")
    proc = run_treegen("make", tmp_path / "nameonly.txt", "-o", tmp_path / "t.glb")
    assert proc.returncode == 2 and proc.stdout == ""
    err = proc.stderr.strip()
    assert "\n" not in err and "Traceback" not in err
    assert "nameonly.txt: missing Shape, BaseSize, Scale, ScaleV, Levels and " in err
    assert "more; a species file lists every parameter" in err and "quaking_aspen.txt" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["nameonly.txt"]


@pytest.mark.parametrize("path", SPECIES + sorted(FIXTURES.glob("*.txt")), ids=lambda p: p.name)
def test_every_required_line_of_a_species_file_is_missed_when_deleted(path):
    """Each bundled (and fixture) text file lists every parameter its tree uses; deleting any
    one of those lines is refused naming exactly that key, deleting an optional one is not."""
    from treegen_cli.params.keys import lookup, required_keys

    text = path.read_text()
    p = parse_params_text(text, path.name)
    required = set(required_keys(p.levels, p.leaves))
    lines = text.split("\n")
    checked = 0
    for i, raw in enumerate(lines):
        key = raw.split("#", 1)[0].replace("=", " ").split()[:1]
        found = lookup(key[0]) if key else None
        if found is None:
            continue
        cut = "\n".join(lines[:i] + lines[i + 1 :])
        if found[2] in ("Levels", "Leaves"):  # they decide which keys are needed: still refused
            with pytest.raises(TreegenError, match=rf"^{path.name}:"):
                parse_params_text(cut, path.name)
            checked += 1
        elif found[2] in required:
            with pytest.raises(TreegenError, match=rf"^{path.name}: missing {found[2]}; a species file"):
                parse_params_text(cut, path.name)
            checked += 1
        else:
            parse_params_text(cut, path.name)  # optional (or unused, like the leaf level's Length)
    assert checked == len(required)


def test_required_keys_follow_levels_and_leaves():
    from treegen_cli.params.keys import OPTIONAL_TOP, required_keys

    three = required_keys(3, 25)
    assert {"1DownAngle", "2Branches", "3DownAngle", "3RotateV"} <= set(three)
    assert not {"3Branches", "3Length", "0DownAngle", "0Branches", "1BranchDist"} & set(three)
    assert not OPTIONAL_TOP & set(three) and "LeafQuality" in OPTIONAL_TOP
    assert "3DownAngle" not in required_keys(3, 0)  # no leaves: nothing to orient
    assert not any(k[0] == "1" for k in required_keys(0, 25))  # a trunk alone
    assert len(required_keys(4, -6)) == len(three) + 15


def test_arbaro_xml_stays_partial_and_the_writer_writes_complete_files():
    xml = "<arbaro><species name='t'><param name='Levels' value='1'/></species></arbaro>"
    p = parse_params_bytes(xml.encode(), "t.xml")  # Arbaro fills its defaults: accepted
    assert p.levels == 1
    for q in (p, default_params(), load_params(FIXTURES / "pair_small.xml")):
        assert parse_params_text(format_params_text(q)) == q  # strict: nothing missing


def test_a_fragment_is_accepted_only_when_asked():
    with pytest.raises(TreegenError, match=r"^x\.txt: missing Shape, .* and \d+ more; "):
        parse_params_text("Levels 2\n", "x.txt")
    assert fragment("Levels 2\n").levels == 2


def test_an_xml_file_that_is_not_xml_says_it_was_read_as_text(tmp_path):
    """An .xml file is read by its content: one that does not start with '<' is read as
    Weber–Penn text, and its error says so (a trial saw only 'unknown key hello'); a real
    Weber–Penn file named .xml still reads, and a text file's message is unchanged."""
    bad = tmp_path / "garbage.xml"
    bad.write_text("hello not xml\n")
    with pytest.raises(TreegenError) as exc:
        load_params(bad)
    assert str(exc.value).startswith(f"{bad}:1: unknown key hello") and "not Arbaro XML" in str(exc.value)
    txt = tmp_path / "garbage.txt"
    txt.write_text("hello not xml\n")
    with pytest.raises(TreegenError) as exc:
        load_params(txt)
    assert "Arbaro" not in str(exc.value)
    binary = tmp_path / "bin.xml"  # refused for its bytes, never read as text: no hint
    binary.write_bytes(b"\x89PNG\r\n\x1a\n\x00\x00")
    with pytest.raises(TreegenError) as exc:
        load_params(binary)
    assert "binary" in str(exc.value) and "Arbaro" not in str(exc.value)
    named = tmp_path / "aspen.xml"
    named.write_bytes((ROOT / "species" / "quaking_aspen.txt").read_bytes())
    assert load_params(named) == load_params(ROOT / "species" / "quaking_aspen.txt")

"""Bundled species by name, from any folder: `treegen make quaking_aspen` works wherever the user
stands, an existing path always wins, every door (make, info, preview, forest layouts, batch
catalogues, api.make) resolves names the same way, and `treegen species` says where they live."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from treegen_cli.bundled import bundled_names, close_matches, resolve_species, species_dir
from treegen_cli.errors import TreegenError

ROOT = Path(__file__).resolve().parent.parent
ENV = {
    **os.environ,
    "PYTHONPATH": os.pathsep.join([str(ROOT), *filter(None, [os.environ.get("PYTHONPATH")])]),
}
FAST = ["--no-lod", "--duration", "1", "--fps", "5", "-q"]


def treegen(*args, cwd):
    """`treegen ARGS` in a fresh process standing in `cwd` (this checkout's package)."""
    return subprocess.run(
        [sys.executable, "-m", "treegen_cli", *map(str, args)],
        capture_output=True,
        text=True,
        env=ENV,
        cwd=cwd,
    )


def test_bundled_species_are_package_data_and_the_repo_link_points_there():
    names = bundled_names()
    assert len(names) >= 15 and "quaking_aspen" in names
    assert all(p.parent == species_dir() for p in names.values())
    assert species_dir().parent == ROOT / "treegen_cli"
    assert (ROOT / "species").resolve() == species_dir()  # README's species/… paths
    # a wheel carries exactly these files: pyproject's package-data globs match them all
    import tomllib

    globs = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["package-data"]
    shipped = {p for g in globs["treegen_cli"] for p in (ROOT / "treegen_cli").glob(g)}
    assert set(names.values()) <= shipped


@pytest.mark.parametrize("name", ["quaking_aspen", "quaking_aspen.txt", "Quaking-Aspen", "QUAKING_ASPEN.TXT"])
def test_names_with_or_without_suffix_resolve_to_the_bundled_file(tmp_path, name, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert resolve_species(name) == species_dir() / "quaking_aspen.txt"


def test_an_existing_path_wins_over_a_bundled_name(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    Path("rush.txt").write_text((species_dir() / "palm.txt").read_text())
    assert resolve_species("rush.txt") == Path("rush.txt")  # the local file
    assert resolve_species("rush") == species_dir() / "rush.txt"  # no such path: the name
    base = tmp_path / "layouts"
    base.mkdir()
    (base / "palm.txt").write_text("Levels 1\n")
    assert resolve_species("palm.txt", base) == base / "palm.txt"  # relative to the file first
    assert resolve_species("palm", base) == species_dir() / "palm.txt"


def test_unknown_names_and_directories_are_one_line_refusals(tmp_path):
    with pytest.raises(TreegenError) as e:
        resolve_species("quaking_apsen")
    msg = str(e.value)
    assert "quaking_apsen" in msg and "did you mean quaking_aspen" in msg and "treegen species" in msg
    assert close_matches("oak") == ["ca_black_oak"]
    with pytest.raises(TreegenError, match="is a directory"):
        resolve_species(str(tmp_path))
    with pytest.raises(TreegenError, match="not found"):
        resolve_species("some/dir/quaking_aspen")  # a path with folders is never a name
    with pytest.raises(TreegenError, match="species 'palm.xml' not found"):
        resolve_species("palm.xml")  # the user's own XML file, missing: not the bundled palm.txt


def test_make_by_name_from_another_folder_writes_the_same_bytes(tmp_path):
    """The README's first command, from a folder that is not the checkout."""
    by_name = treegen("make", "rush", "-o", "by_name.glb", *FAST, cwd=tmp_path)
    assert by_name.returncode == 0, by_name.stderr
    by_path = treegen("make", species_dir() / "rush.txt", "-o", "by_path.glb", *FAST, cwd=tmp_path)
    assert by_path.returncode == 0, by_path.stderr
    a, b = (tmp_path / "by_name.glb").read_bytes(), (tmp_path / "by_path.glb").read_bytes()
    assert a[:4] == b"glTF" and a == b


def test_info_by_name_and_path_wins_through_the_cli(tmp_path):
    (tmp_path / "rush.txt").write_text((species_dir() / "palm.txt").read_text())
    local = treegen("info", "rush.txt", "--json", cwd=tmp_path)
    bundled = treegen("info", "rush", "--json", cwd=tmp_path)
    assert local.returncode == bundled.returncode == 0, local.stderr + bundled.stderr
    assert json.loads(local.stdout)["species"] == "palm"
    assert json.loads(bundled.stdout)["species"] == "rush"


@pytest.mark.parametrize(
    "args, needles",
    [
        (
            ["make", "quaking_apsen", "-o", "x.glb"],
            ["'quaking_apsen' not found", "did you mean quaking_aspen"],
        ),
        (["info", "nothing_like_it"], ["'nothing_like_it' not found", "treegen species"]),
        (["make", ".", "-o", "x.glb"], ["'.' is a directory", "bundled species name"]),
        (["info", "."], ["'.' is a directory"]),
        (["preview", "quaking_apsen", "-o", "x.png"], ["'quaking_apsen' not found", "quaking_aspen"]),
        (["preview", ".", "-o", "x.png"], [". is a directory", "bundled species name"]),
    ],
)
def test_bad_species_arguments_exit_2_with_one_line(tmp_path, args, needles):
    proc = treegen(*args, cwd=tmp_path)
    assert proc.returncode == 2 and proc.stdout == ""
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("treegen: error: "), proc.stderr
    assert all(n in lines[0] for n in needles), lines[0]
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("command", ["make", "info"])
def test_a_written_tree_given_as_species_is_named_as_such(tmp_path, command):
    """`treegen info tree.glb` (or make) read the GLB as a species text and refused it for a NUL
    byte at "line 1"; now it says what the file is and what reads it."""
    (tmp_path / "tree.glb").write_bytes(b"glTF\x02\x00\x00\x00")
    args = [command, "tree.glb"] + (["-o", "x.glb"] if command == "make" else [])
    proc = treegen(*args, cwd=tmp_path)
    assert proc.returncode == 2 and proc.stdout == ""
    (line,) = proc.stderr.strip().splitlines()
    assert "'tree.glb' is a written tree (.glb), not a species file" in line, line
    assert "treegen preview tree.glb -o tree.png" in line
    assert sorted(p.name for p in tmp_path.iterdir()) == ["tree.glb"]


def test_preview_input_resolves_names(tmp_path, monkeypatch):
    from treegen_cli.preview import resolve_input

    monkeypatch.chdir(tmp_path)
    assert resolve_input("palm") == species_dir() / "palm.txt"
    Path("palm.glb").write_bytes(b"")
    assert resolve_input("palm.glb") == Path("palm.glb")  # a written tree stays a file
    assert resolve_input("missing.glb") == Path("missing.glb")  # exchange names what is missing


def test_layouts_and_catalogues_take_names_relative_paths_first(tmp_path):
    from treegen_cli.batch import parse_catalogue
    from treegen_cli.forest.layout import parse_layout

    (tmp_path / "rush.txt").write_text((species_dir() / "palm.txt").read_text())
    layout = {
        "camera": {"position": [0, -20, 2], "target": [0, 0, 2]},
        "instances": [
            {"species": "rush.txt", "position": [0, 0]},
            {"species": "quaking_aspen", "position": [5, 0]},
        ],
    }
    placed = parse_layout(layout, tmp_path / "layout.json").placements
    assert [p.species for p in placed] == [
        (tmp_path / "rush.txt").resolve(),
        species_dir() / "quaking_aspen.txt",
    ]
    catalogue = {"entries": [{"species": "rush.txt"}, {"species": "quaking_aspen.txt", "seeds": [1]}]}
    jobs = parse_catalogue(catalogue, tmp_path / "catalogue.json").jobs
    assert [j.species for j in jobs] == [
        (tmp_path / "rush.txt").resolve(),
        species_dir() / "quaking_aspen.txt",
    ]
    with pytest.raises(
        TreegenError,
        match=r"entries\[0\].species: species file 'quaking' not found.*"
        r"did you mean quaking_aspen",
    ):
        parse_catalogue({"entries": [{"species": "quaking"}]}, tmp_path / "catalogue.json")
    with pytest.raises(TreegenError, match=r"instances\[0\].species: species file 'tupelo' not found"):
        parse_layout(
            {**layout, "instances": [{"species": "tupelo", "position": [0, 0]}]}, tmp_path / "layout.json"
        )


def test_api_make_takes_a_name(tmp_path):
    from treegen_cli import api

    s = api.make("rush", tmp_path / "r.glb", no_lod=True, duration=1, fps=5)
    assert s["species"] == "rush" and (tmp_path / "r.glb").stat().st_size == s["bytes"]


def test_species_command_lists_names_and_where_they_come_from(tmp_path):
    proc = treegen("species", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    head, _columns, *rows = proc.stdout.splitlines()
    assert str(species_dir()) in head and "treegen make" in head
    assert [r.split()[0] for r in rows] == sorted(bundled_names())
    assert all(len(r.split()) >= 5 for r in rows)  # stems, leaves, height, description
    listed = json.loads(treegen("species", "--json", cwd=tmp_path).stdout)
    assert {r["name"]: Path(r["path"]) for r in listed} == bundled_names()
    for r in listed:  # every listed name is accepted
        assert resolve_species(r["name"]) == Path(r["path"])

"""`treegen species`: the bundled species files, what each one is, and how big it grows.

The files are package data (treegen_cli/species/, see bundled.py); any command takes a name
from this list in place of a species file. Each file's header comment names the tree on its
first line and its origin on a "Source:" line; counts come from growing it at the default seed
(tens of ms each, the willow about a second).
"""
from __future__ import annotations

import json
import re
from dataclasses import asdict, dataclass
from pathlib import Path

import click

from .bundled import species_dir, species_files


@dataclass(frozen=True)
class SpeciesInfo:
    name: str            # file stem, what `treegen make <name>` takes
    path: str
    description: str     # one line: the tree's name and where its values come from
    stems: int           # at the default seed
    leaves: int
    height_m: float


def describe(path: Path) -> str:
    """One line from the header: "<title> — <source>". A title that only repeats the file
    name is spelled as words ("fan_palm" → "Fan palm")."""
    header = []
    for line in path.read_text(encoding="utf-8", errors="replace").splitlines():
        if not line.startswith("#"):
            if line.strip():
                break
            continue
        header.append(line.lstrip("#").strip())
    title = header[0] if header else path.stem
    if title.replace(" ", "_").lower() == path.stem.lower():
        title = path.stem.replace("_", " ").capitalize()
    source = next((h.split(":", 1)[1].strip() for h in header if h.lower().startswith("source:")), "")
    if source.lower().startswith("no "):         # "no paper values exist ...; taken from X"
        m = re.search(r"taken from ([\w./-]+)", " ".join(header))
        source = m.group(1) if m else ""
    source = re.split(r"[,(]", source)[0].strip().rstrip(".")
    if source.lower().startswith("arbaro"):
        m = re.search(r"trees/\S+", source)
        source = f"Arbaro {m.group(0)}" if m else "Arbaro"
    return f"{title} — {source}" if source else title


def species_info(path: Path, seed: int = 0) -> SpeciesInfo:
    from .generate import generate
    from .params import load_params
    from .tree import tree_stats

    tree = generate(load_params(path), seed)
    stats = tree_stats(tree)
    return SpeciesInfo(name=path.stem, path=str(path), description=describe(path),
                       stems=int(tree.n_stems), leaves=int(tree.n_leaves),
                       height_m=round(float(stats["height_m"]), 2))


def list_species(seed: int = 0, folder: Path | None = None) -> list[SpeciesInfo]:
    return [species_info(p, seed) for p in species_files(folder)]


def as_dicts(infos: list[SpeciesInfo]) -> list[dict]:
    return [asdict(i) for i in infos]


@click.command("species")
@click.option("--seed", type=int, default=0, show_default=True,
              help="Seed the counts are grown with.")
@click.option("--json", "as_json", is_flag=True, help="Print the list as JSON.")
def species_command(seed, as_json):
    """List the bundled species: name, one-line description (the tree and where its values
    come from), and stems, leaves and height (m) when grown at SEED. Any command takes a name
    in place of a species file, from any folder: `treegen make quaking_aspen -o aspen.glb`."""
    infos = list_species(seed)
    if as_json:
        click.echo(json.dumps(as_dicts(infos), indent=2, ensure_ascii=False))
        return
    width = max(len(i.name) for i in infos) if infos else 4
    click.echo(f"bundled species, from {species_dir()} (seed {seed}); a name works anywhere a "
               f"species file does, e.g. treegen make {infos[0].name if infos else 'NAME'} -o tree.glb")
    click.echo(f"{'species':<{width}}  {'stems':>7}  {'leaves':>8}  {'height':>7}  description")
    for i in infos:
        click.echo(f"{i.name:<{width}}  {i.stems:>7,}  {i.leaves:>8,}  {i.height_m:>6.1f}m  "
                   f"{i.description}")

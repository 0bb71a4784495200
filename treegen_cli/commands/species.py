"""`treegen species`: the bundled species with a line each (species_list.py finds and grows them)."""

from __future__ import annotations

import json

import click

from ..bundled import species_dir
from ..species_list import as_dicts, list_species
from . import flags


@click.command("species")
@click.option("--seed", type=int, default=0, show_default=True, help="Seed the counts are grown with.")
@flags.json_flag("Print the list as JSON.")
def species(seed, as_json):
    """List the bundled species: name, one-line description (the tree and where its values
    come from), and stems, leaves and height (m) when grown at SEED. Any command takes a name
    in place of a species file, from any folder: `treegen make quaking_aspen -o aspen.glb`."""
    infos = list_species(seed)
    if as_json:
        click.echo(json.dumps(as_dicts(infos), indent=2, ensure_ascii=False))
        return
    width = max(len(i.name) for i in infos) if infos else 4
    click.echo(
        f"bundled species, from {species_dir()} (seed {seed}); a name works anywhere a "
        f"species file does, e.g. treegen make {infos[0].name if infos else 'NAME'} -o tree.glb"
    )
    click.echo(f"{'species':<{width}}  {'stems':>7}  {'leaves':>8}  {'height':>7}  description")
    for i in infos:
        click.echo(f"{i.name:<{width}}  {i.stems:>7,}  {i.leaves:>8,}  {i.height_m:>6.1f}m  {i.description}")

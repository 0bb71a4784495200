"""`treegen species`: the bundled species files, what each one is, and how big it grows.

The files are package data (treegen_cli/species/, see bundled.py); any command takes a name
from this list in place of a species file. Each file's header comment names the tree on its
first line and its origin on a "Source:" line; counts come from growing it at the default seed
(tens of ms each, the willow about a second).
"""

from __future__ import annotations

import re
from dataclasses import asdict, dataclass
from pathlib import Path


from .bundled import species_dir, species_files  # noqa: F401  (species_dir: re-exported)


@dataclass(frozen=True)
class SpeciesInfo:
    name: str  # file stem, what `treegen make <name>` takes
    path: str
    description: str  # one line: the tree's name and where its values come from
    stems: int  # at the default seed
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
    if source.lower().startswith("no "):  # "no paper values exist ...; taken from X"
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
    return SpeciesInfo(
        name=path.stem,
        path=str(path),
        description=describe(path),
        stems=int(tree.n_stems),
        leaves=int(tree.n_leaves),
        height_m=round(float(stats["height_m"]), 2),
    )


def list_species(seed: int = 0, folder: Path | None = None) -> list[SpeciesInfo]:
    return [species_info(p, seed) for p in species_files(folder)]


def as_dicts(infos: list[SpeciesInfo]) -> list[dict]:
    return [asdict(i) for i in infos]

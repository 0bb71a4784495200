"""Bundled species: the files shipped inside the package (treegen_cli/species/), found by name.

Every door that takes a species (`treegen make`, `info`, `preview`, forest layouts, batch
catalogues, `api.make`) resolves it here, so they all agree:

    resolve_species("quaking_aspen")          # → <package>/species/quaking_aspen.txt
    resolve_species("my_oak.txt")             # → my_oak.txt, when that file exists
    resolve_species("oak.txt", base=folder)   # → folder/oak.txt (layouts, catalogues)

A path that exists always wins; otherwise a bare name (no folder part), with or without its
suffix, is looked up among the bundled species. The species live in the package so that a
wheel installed anywhere carries them (the repository's `species/` is a link to this folder).
"""

from __future__ import annotations

import difflib
import os
from pathlib import Path

from .errors import TreegenError

SUFFIXES = (".txt", ".xml")  # species files: Weber–Penn text or Arbaro XML (params/)
LIST_HINT = "`treegen species` lists the bundled ones"
WRITTEN = (".glb", ".gltf", ".usd", ".usda", ".usdc", ".usdz", ".obj")  # what make writes


def species_dir() -> Path:
    """The bundled species folder, package data beside this module."""
    return Path(__file__).resolve().parent / "species"


def species_files(folder: Path | None = None) -> list[Path]:
    folder = folder or species_dir()
    if not folder.is_dir():
        raise TreegenError(f"bundled species folder not found ({folder}); reinstall treegen")
    return sorted(p for p in folder.iterdir() if p.suffix.lower() in SUFFIXES and p.is_file())


def bundled_names() -> dict[str, Path]:
    """name → file of every bundled species (`quaking_aspen` → …/quaking_aspen.txt)."""
    return {p.stem: p for p in species_files()}


def _key(name: str) -> str:
    """Names compare case-blind, with '-' or ' ' for '_' (`Quaking-Aspen` is quaking_aspen)."""
    return name.strip().lower().replace("-", "_").replace(" ", "_")


def bundled_species(name: str) -> Path | None:
    """The bundled file `name` (a bare name, suffix optional) stands for, or None."""
    if not name or "/" in name or os.sep in name or (os.altsep and os.altsep in name):
        return None
    suffix = Path(name).suffix.lower()
    stem = name[: -len(suffix)] if suffix in SUFFIXES else name
    by_key = {_key(n): p for n, p in bundled_names().items()}
    hit = by_key.get(_key(stem))
    if hit is not None and suffix in SUFFIXES and suffix != hit.suffix.lower():
        return None  # `palm.xml` is the user's own XML file, missing here: not palm.txt
    return hit


def close_matches(name: str, n: int = 3) -> list[str]:
    """Bundled names close to `name`'s stem, best first (for 'did you mean')."""
    stem = Path(str(name).replace("\\", "/")).name
    stem = stem[: -len(Path(stem).suffix)] if Path(stem).suffix.lower() in SUFFIXES else stem
    names = sorted(bundled_names())
    keys = {_key(x): x for x in names}
    hits = difflib.get_close_matches(_key(stem), list(keys), n=n, cutoff=0.5)
    hits += [k for k in keys if _key(stem) and _key(stem) in k and k not in hits][: n - len(hits)]
    return [keys[h] for h in hits]


def not_found(subject: str, value: str) -> TreegenError:
    """The one-line refusal for a species argument that is neither a file nor a bundled name."""
    hits = close_matches(value)
    hint = f"did you mean {', '.join(hits)}? ({LIST_HINT})" if hits else LIST_HINT
    return TreegenError(f"{subject} not found (no such file, and no bundled species by that name); {hint}")


def resolve_species(value: str | os.PathLike, base: Path | None = None, subject: str | None = None) -> Path:
    """The species file `value` names: an existing path (relative to `base` if given, else to
    the working folder) first, then a bundled name. Otherwise a one-line TreegenError that
    starts with `subject` (default: "species 'VALUE'"; layouts and catalogues pass their JSON
    path)."""
    text = os.fspath(value)
    subject = subject or f"species '{text}'"
    path = Path(base, text) if base is not None else Path(text)
    try:
        is_dir, is_file = path.is_dir(), path.is_file()
    except (OSError, ValueError):  # e.g. a NUL byte or an over-long name
        is_dir = is_file = False
    if is_dir:
        raise TreegenError(
            f"{subject} is a directory; expected a species file "
            f"({' '.join(SUFFIXES)}) or a bundled species name such as "
            f"quaking_aspen ({LIST_HINT})"
        )
    if is_file and path.suffix.lower() in WRITTEN:
        raise TreegenError(
            f"{subject} is a written tree ({path.suffix.lower()}), not a species file: give a "
            f"Weber–Penn .txt or Arbaro .xml file or a bundled name ({LIST_HINT}); "
            f"`treegen preview {text} -o tree.png` renders a written tree"
        )
    if is_file and path.suffix.lower() == ".json":
        raise TreegenError(
            f"{subject} is a JSON file, not a species file: a forest layout is built with "
            f"`treegen forest {path} -o forest.glb`, a catalogue with `treegen batch {path} -o DIR`"
        )
    if is_file:
        return path
    hit = bundled_species(text)
    if hit is not None:
        return hit
    raise not_found(subject, text)

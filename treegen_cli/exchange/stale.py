"""Files an earlier write to the same output left that this one did not write, removed once the
new files are in place: a `--lod-files` run with fewer LODs left NAME_LOD3.glb … beside the new
parts (engines import parts by name, so Unity and Godot took the old ones), and a run without
an impostor left the sidecar and atlas PNGs describing an impostor the file no longer has.

Textures are the earlier file's own: the PNGs beside it that the old .usda/.usdc (its asset
paths), .gltf (its images' URIs) or .obj (its .mtl's maps) named with this output's prefix, read before it is replaced,
and not written again (a `--no-textures` rerun, a forest whose prototypes changed).

Otherwise only exact names treegen gives this output are touched: NAME.ext's sidecar and impostor PNGs
(NAME_ext_impostor_albedo.png …; not a prefix, so `a.usda` never touches `a_usda.usda`'s), the
parts NAME_LODk.ext (a .gltf part's NAME_LODk.bin), their sidecars, and the parts' impostor
PNGs (NAME_LOD_ext_impostor_….png: the parts' textures have their own prefix, PARTS_TAG). The
single file and the parts are separate outputs and never remove each other's files.

    remove_stale(Path("a.glb"), written, parts=3)   # a_LOD3.glb, a_LOD4.glb … gone
"""

from __future__ import annotations

import json
import re
from pathlib import Path
from urllib.parse import unquote

IMPOSTOR_PNGS = ("impostor_albedo", "impostor_normal", "impostor_cards", "impostor_cards_normal")
# a material library's texture line: the name is the rest of the line after the options
# (`map_Bump -bm 1.000000 my tree_obj_bark_normal.png`: names may hold spaces)
_MAP = re.compile(r"^(?:map_\w+|bump)\s+(?:-\w+\s+\S+\s+)*(.+?)\s*$")
PARTS_TAG = "_LOD"  # the parts' shared textures: NAME_LOD_usdc_leaf.png (texture_files)


def _named_textures(file: Path) -> list[str]:
    """PNG names (relative) an earlier output file refers to: a USD layer's asset paths, a
    .gltf's image URIs, an OBJ's material library maps; none for a file that is not one (or not readable)."""
    suffix = file.suffix.lower()
    try:
        if suffix in (".usda", ".usdc"):
            from pxr import UsdUtils

            _, assets, _ = UsdUtils.ExtractExternalReferences(str(file))
        elif suffix == ".obj":
            mtl = file.with_suffix(".mtl").read_text(encoding="utf-8", errors="replace")
            assets = [m[1] for m in map(_MAP.match, mtl.splitlines()) if m]
        elif suffix == ".gltf":
            images = json.loads(file.read_text(encoding="utf-8")).get("images", [])
            assets = [unquote(i["uri"]) for i in images if not i.get("uri", "data:").startswith("data:")]
        else:
            return []
    except Exception:  # (not treegen's, unreadable: nothing it names is ours to remove)
        return []
    return [a[2:] if a.startswith("./") else a for a in assets if a.lower().endswith(".png")]


def earlier_textures(path: Path, parts: int | None = None) -> list[Path]:
    """The texture PNGs the files an earlier write to `path` left (one file, or its parts)
    name beside them with this output's texture prefix: read before they are replaced."""
    prefix = path.stem + (PARTS_TAG if parts is not None else "") + path.suffix.replace(".", "_", 1) + "_"
    if parts is None:
        files = [path]
    else:
        part = re.compile(rf"^{re.escape(path.stem)}_LOD\d+{re.escape(path.suffix)}$")
        try:
            files = sorted(p for p in path.parent.iterdir() if part.match(p.name))
        except OSError:
            files = []
    names = {n for f in files if f.is_file() for n in _named_textures(f)}
    return [path.parent / n for n in sorted(names) if n.startswith(prefix) and "/" not in n]


def stale_files(
    path: Path, written: list[Path], parts: int | None = None, earlier: list[Path] = ()
) -> list[Path]:
    """What to remove beside `path` (NAME.ext) after writing `written`, as one file (`parts`
    None) or as `parts` parts; `earlier`: earlier_textures, read before the write."""
    stem, e = re.escape(path.stem), re.escape(path.suffix)
    tag = re.escape(path.suffix.replace(".", "_", 1))  # textures: NAME_usdc_impostor_albedo.png
    pngs = "|".join(IMPOSTOR_PNGS)
    if parts is None:
        pattern = rf"^{stem}(?:{e}\.impostor\.json|{tag}_(?:{pngs})\.png)$"
    else:
        bin_ = r"|\.bin" if path.suffix.lower() == ".gltf" else ""
        pattern = (
            rf"^{stem}_LOD(?P<k>\d+)(?:{e}{bin_})$"  # a part, numbered from `parts` on
            rf"|^{stem}_LOD\d+{e}\.impostor\.json$"
            rf"|^{stem}{re.escape(PARTS_TAG)}{tag}_(?:{pngs})\.png$"
        )
    match = re.compile(pattern)
    try:
        names = sorted(p.name for p in path.parent.iterdir() if p.is_file())
    except OSError:
        return []
    new = {p.name for p in written}
    drop = [p.name for p in earlier if p.name not in new and p.name in names]
    for n in names:
        m = match.match(n)
        if m is None or n in new:
            continue
        k = m.groupdict().get("k")
        if k is None or int(k) >= (parts or 0):
            drop.append(n)
    return [path.parent / n for n in sorted(set(drop))]


def remove_stale(
    path: Path, written: list[Path], parts: int | None = None, earlier: list[Path] = ()
) -> list[Path]:
    """Remove `stale_files` (one that cannot be removed stays); returns what was removed."""
    removed = []
    for p in stale_files(path, written, parts, earlier):
        try:
            p.unlink()
            removed.append(p)
        except OSError:
            pass
    return removed

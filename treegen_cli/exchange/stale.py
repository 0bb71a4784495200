"""Files an earlier write to the same output left that this one did not write, removed once the
new files are in place: a `--lod-files` run with fewer LODs left NAME_LOD3.glb … beside the new
parts (engines import parts by name, so Unity and Godot took the old ones), and a run without
an impostor left the sidecar and atlas PNGs describing an impostor the file no longer has.

Only exact names treegen gives this output are touched: NAME.ext's sidecar and impostor PNGs
(NAME_ext_impostor_albedo.png …; not a prefix, so `a.usda` never touches `a_usda.usda`'s), the
parts NAME_LODk.ext (a .gltf part's NAME_LODk.bin), their sidecars, and the parts' impostor
PNGs (NAME_LOD_ext_impostor_….png: the parts' textures have their own prefix, PARTS_TAG). The
single file and the parts are separate outputs and never remove each other's files.

    remove_stale(Path("a.glb"), written, parts=3)   # a_LOD3.glb, a_LOD4.glb … gone
"""

from __future__ import annotations

import re
from pathlib import Path

IMPOSTOR_PNGS = ("impostor_albedo", "impostor_normal", "impostor_cards", "impostor_cards_normal")
PARTS_TAG = "_LOD"  # the parts' shared textures: NAME_LOD_usdc_leaf.png (texture_files)


def stale_files(path: Path, written: list[Path], parts: int | None = None) -> list[Path]:
    """What to remove beside `path` (NAME.ext) after writing `written`, as one file (`parts`
    None) or as `parts` parts."""
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
    drop = []
    for n in names:
        m = match.match(n)
        if m is None or n in new:
            continue
        k = m.groupdict().get("k")
        if k is None or int(k) >= (parts or 0):
            drop.append(n)
    return [path.parent / n for n in drop]


def remove_stale(path: Path, written: list[Path], parts: int | None = None) -> list[Path]:
    """Remove `stale_files` (one that cannot be removed stays); returns what was removed."""
    removed = []
    for p in stale_files(path, written, parts):
        try:
            p.unlink()
            removed.append(p)
        except OSError:
            pass
    return removed

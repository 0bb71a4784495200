"""Files an earlier write to the same output left that this one did not write, removed once the
new files are in place: a `--lod-files` run with fewer LODs left NAME_LOD3.glb … beside the new
parts (engines import parts by name, so Unity and Godot took the old ones), and a run without
an impostor left the sidecar and atlas PNGs describing an impostor the file no longer has.

Only names treegen gives to this output are touched: NAME.ext's sidecar and textures, the
parts NAME_LODk.ext (a .gltf part's .bin) and their sidecars and textures. The single file and
the parts are separate outputs: writing one never removes the other, nor the textures named
after NAME.ext while the other is there to use them (USD parts share the single file's names).

    remove_stale(Path("a.glb"), written, parts=3)   # a_LOD3.glb, a_LOD4.glb … gone
"""

from __future__ import annotations

import re
from pathlib import Path


def stale_files(path: Path, written: list[Path], parts: int | None = None) -> list[Path]:
    """What to remove beside `path` (NAME.ext) after writing `written`, as one file (`parts`
    None) or as `parts` parts."""
    stem, e = re.escape(path.stem), re.escape(path.suffix)
    tag = re.escape(path.suffix.replace(".", "_", 1))  # textures: NAME_usdc_leaf.png
    sidecar = re.compile(rf"^{stem}{e}\.impostor\.json$")
    textures = re.compile(rf"^{stem}{tag}_\w+\.png$")
    part = re.compile(rf"^{stem}_LOD(\d+)(?:{e}|\.bin)$")
    part_extra = re.compile(rf"^{stem}_LOD\d+(?:{e}\.impostor\.json|{tag}_\w+\.png)$")
    try:
        names = sorted(p.name for p in path.parent.iterdir() if p.is_file())
    except OSError:
        return []
    new = {p.name for p in written}
    if parts is None:
        other = any(part.match(n) for n in names)  # parts that may use the textures
        drop = [n for n in names if sidecar.match(n) or (textures.match(n) and not other)]
    else:
        other = path.name in names  # the single file, which may use them
        drop = [
            n
            for n in names
            if ((m := part.match(n)) and int(m.group(1)) >= parts)
            or part_extra.match(n)
            or (textures.match(n) and not other)
        ]
    return [path.parent / n for n in drop if n not in new]


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

"""Every file treegen reads or writes passes through here: one table per direction and kind,
keyed by suffix, and the only place a suffix is checked.

    export(asset, "tree.glb")            # a prepared Asset   → .glb .gltf .usda .usdc .usdz .obj .ply
    export(asset, "tree.glb", GltfOptions(compress="meshopt"))   # glTF only: compress.py
    export_parts(split_lods(asset), "tree.glb")   # → tree_LOD0.glb, tree_LOD1.glb, …
    export_forest(forest, "forest.usdc") # a prepared Forest  → .glb .gltf .usda .usdc .usdz
    save_still(pixels, "tree.png")       # an RGB image       → .png .jpg .jpeg;  save_loop → .gif
    read_drawable("tree.usdz", lod=1)    # a written tree     → drawable.Drawable (preview, tests)

Writing is atomic (staging.staged): a writer writes `path` (and any siblings, such as a
.gltf's .bin) into a hidden staging folder, which is moved into place only when it succeeded.
A writer is `writer(thing, path)` and only encodes; to add a format, add one table entry.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Callable

import numpy as np

from ..asset import Asset, Forest
from ..errors import TreegenError
from ..key_plan import with_key_plans
from ..prepare import with_bounds
from . import gltf, image, read_gltf
from .compress import COMPRESS, GLTF_DEFAULTS, GltfOptions, check_encoder  # noqa: F401  (re-exported)
from .forest_gltf import write_forest_gltf
from .staging import staged, sweep, written  # noqa: F401  (re-exported)
from .stale import PARTS_TAG, earlier_textures, remove_stale


def _usd(asset: Asset, path: Path, textures=None) -> None:
    from .usd import write_usd  # lazy: pxr takes ~0.5 s to import; most runs write glTF

    write_usd(with_bounds(asset), path, textures)  # UsdSkel stores animated extents; only USD pays for them


def _forest_usd(forest: Forest, path: Path) -> None:
    from .forest_usd import write_forest_usd  # lazy: pxr (see _usd)

    write_forest_usd(forest, path)


def _static(asset: Asset, path: Path) -> None:
    from .static import write_static  # lazy: trimesh is slow to import

    write_static(asset, path)


def _read_usd(path: Path, lod: int, refuse_forest: bool = False):
    from .read_usd import read_drawable  # lazy: pxr (see _usd)

    return read_drawable(path, lod)  # refuses a forest either way: no tree outside its instances


WRITERS: dict[str, Callable[[Asset, Path], None]] = {
    ".glb": gltf.write_gltf,
    ".gltf": gltf.write_gltf,
    ".usda": _usd,
    ".usdc": _usd,
    ".usdz": _usd,
    ".obj": _static,
    ".ply": _static,
}
FOREST_WRITERS: dict[str, Callable[[Forest, Path], None]] = {
    ".glb": write_forest_gltf,
    ".gltf": write_forest_gltf,
    ".usda": _forest_usd,
    ".usdc": _forest_usd,
    ".usdz": _forest_usd,
}
READERS: dict[str, Callable[[Path, int, bool], object]] = {
    ".glb": read_gltf.read_drawable,
    ".gltf": read_gltf.read_drawable,
    ".usd": _read_usd,
    ".usda": _read_usd,
    ".usdc": _read_usd,
    ".usdz": _read_usd,
}
SPECIES = (".txt", ".xml")  # species files: read by params/ (text or Arbaro XML)
STILLS = (".png", ".jpg", ".jpeg")
LOOPS = (".gif",)
STATIC = (".obj", ".ply")  # formats with no skin or animation
FIXED_UP_AXIS = {".glb": "y", ".gltf": "y"}  # glTF is Y up by spec; the rest take Asset.up_axis


def supported_suffixes(table: dict | tuple = WRITERS) -> list[str]:
    return sorted(table)


def check_suffix(
    path: str | os.PathLike, table: dict | tuple = WRITERS, kind: str = "output", flag: str | None = None
) -> Path:
    """`path` as a Path, or the one-line error naming the extensions `table` supports.
    `flag` is how the user gave the path (`-o`, `--animate`), named first in the message."""
    path = Path(path)
    suffix = path.suffix.lower()
    allowed = " ".join(supported_suffixes(table))
    who = f"{flag} {path}" if flag else str(path)
    if kind != "input" and path.is_dir():
        raise TreegenError(
            f"{who}: is a directory; give a file name ending in one of {allowed} "
            f"(e.g. {path / ('tree' + next(iter(table)))})"
        )
    if not suffix:
        raise TreegenError(
            f"{who}: no file extension; the extension picks the {kind} format, one of {allowed}"
        )
    if suffix not in table:
        raise TreegenError(f"{who}: unknown {kind} extension '{suffix}'; allowed: {allowed}")
    return path


def check_up_axis(path: str | os.PathLike, up: str | None) -> None:
    """The one-line error for an up axis the format cannot carry (None: the format's default)."""
    if up is None:
        return
    if str(up).lower() not in ("y", "z"):
        raise TreegenError(f"up axis '{up}': expected y or z")
    fixed = FIXED_UP_AXIS.get(Path(path).suffix.lower())
    if fixed and str(up).lower() != fixed:
        others = " ".join(s for s in supported_suffixes() if s not in FIXED_UP_AXIS)
        raise TreegenError(f"{path}: glTF is always Y up; up axis {up} needs one of {others}")


def check_compress(path: str | os.PathLike, compress: str, flag: str = "--compress") -> None:
    """The one-line error for a compression the output format cannot carry (glTF only)."""
    if compress not in COMPRESS:
        raise TreegenError(f"{flag} {compress!r}: use one of {', '.join(COMPRESS)}")
    suffix = Path(path).suffix.lower()
    if compress != "none" and suffix not in FIXED_UP_AXIS:
        why = (
            "USD has no such encoding; .usdc is already compact"
            if suffix.startswith(".usd")
            else f"{suffix} has no such encoding"
        )
        raise TreegenError(f"{path}: {flag} {compress} is for .glb/.gltf only ({why}); use {flag} none")
    if compress == "meshopt":
        check_encoder()


def _writer(path: Path, options: GltfOptions) -> Callable[..., None]:
    """The table's writer for `path`; glTF writers get the encoding options. Each takes
    (asset, target) and, where the format writes PNGs beside the file, their names
    (`textures`, texture_files.TextureFiles)."""
    check_compress(path, options.compress)
    writer = WRITERS[path.suffix.lower()]
    if options == GLTF_DEFAULTS:
        return writer
    if options.quantized:  # LOD0's keys planned within 1 mm before the writer encodes them

        def compressed(asset: Asset, target: Path, textures=None) -> None:
            planned = with_key_plans(asset, options.compress == "meshopt")
            gltf.write_gltf(planned, target, options=options, textures=textures)

        return compressed

    def encoded(asset: Asset, target: Path, textures=None) -> None:
        gltf.write_gltf(asset, target, options=options, textures=textures)

    return encoded


def _write(
    writer: Callable[[Path], None], path: Path, after: Callable[[list[Path]], object] | None = None
) -> list[Path]:
    """Stage, write and move into place; `after(files written)` runs once they are in place,
    before a held Ctrl-C acts (staging.staged): an earlier write's extra parts go with it."""
    out: list[Path] = []
    with staged(path, None if after is None else lambda: after(out)) as tmp:
        writer(tmp)
        out[:] = written(tmp, path)
    return out


def export(asset: Asset, path: str | os.PathLike, options: GltfOptions = GLTF_DEFAULTS) -> list[Path]:
    """Write a prepared `asset` in the format `path`'s suffix names, atomically. Returns the
    files written, main file first (a .gltf also writes its .bin)."""
    path = check_suffix(path, WRITERS)
    check_up_axis(path, asset.up_axis)
    writer = _writer(path, options)
    earlier = earlier_textures(path)
    # an earlier write's sidecar, atlas or textures go as the new files land
    return _write(lambda tmp: writer(asset, tmp), path, lambda out: remove_stale(path, out, earlier=earlier))


def lod_file_paths(path: str | os.PathLike, count: int) -> list[Path]:
    """NAME_LOD0.ext … for `path` = NAME.ext: the names Unity's LODGroup and Unreal's per-LOD
    import look for."""
    path = Path(path)
    return [path.with_name(f"{path.stem}_LOD{k}{path.suffix}") for k in range(count)]


def export_parts(
    parts: list[Asset], path: str | os.PathLike, options: GltfOptions = GLTF_DEFAULTS
) -> list[Path]:
    """Each asset of `parts` to its own file (lod_file_paths), all or nothing: every part is
    staged in one folder and moved into place only when all were written."""
    path = check_suffix(path, WRITERS)
    writer = _writer(path, options)
    targets = lod_file_paths(path, len(parts))
    if path.suffix.lower() in (".usda", ".usdc", ".gltf"):  # the parts share one set of textures beside
        from .texture_files import TextureFiles

        # NAME_LOD_usdc_leaf.png: not the single file's names, which it may overwrite with its own
        names = TextureFiles(path.with_name(f"{path.stem}{PARTS_TAG}{path.suffix}"))

        base = writer

        def writer(part: Asset, target: Path) -> None:
            base(part, target, textures=names.shared())

    def write_all(tmp: Path) -> None:
        for part, target in zip(parts, targets):  # a handful of LODs
            writer(part, tmp.parent / target.name)

    earlier = earlier_textures(path, len(parts))
    # an earlier write's parts beyond these, and their extras, go as the new parts land
    return _write(write_all, targets[0], lambda out: remove_stale(path, out, len(parts), earlier))


def export_forest(
    forest: Forest, path: str | os.PathLike, options: GltfOptions = GLTF_DEFAULTS
) -> list[Path]:
    """Write a prepared forest, atomically; the suffix picks glTF or USD (`options`: glTF only)."""
    path = check_suffix(path, FOREST_WRITERS)
    check_compress(path, options.compress)
    writer = FOREST_WRITERS[path.suffix.lower()]
    earlier = earlier_textures(path)

    def stale(out: list[Path]) -> None:  # an earlier forest's prototypes' textures
        remove_stale(path, out, earlier=earlier)

    if options != GLTF_DEFAULTS:
        return _write(lambda tmp: write_forest_gltf(forest, tmp, options=options), path, stale)
    return _write(lambda tmp: writer(forest, tmp), path, stale)


def check_input(path: str | os.PathLike) -> Path:
    """A species file or a written tree that exists, or the one-line error saying what is read."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in READERS and suffix not in (*WRITERS, *STILLS, *LOOPS) and path.is_file():
        return path  # a species file whatever its name (myoak.species): make reads it so
    if suffix not in SPECIES and suffix not in READERS:
        raise TreegenError(
            f"{path}: unknown input extension '{suffix or '(none)'}'; expected a "
            f"species file ({' '.join(SPECIES)}) or a written tree "
            f"({' '.join(supported_suffixes(READERS))})"
        )
    if not path.is_file():
        raise TreegenError(f"{path}: no such file")
    return path


def is_species(path: Path) -> bool:
    """Not a written tree's format: a species file (.txt, .xml, or any name check_input takes)."""
    return path.suffix.lower() not in READERS


def read_drawable(path: str | os.PathLike, lod: int = 0, refuse_forest: bool = False):
    """A written tree (glTF or UsdSkel) as a drawable.Drawable posed by the file's own skin.
    A forest (`treegen forest`) reads as its first tree, or with `refuse_forest` raises the one
    line saying it is a forest (USD forests always do: their trees are all instances)."""
    path = check_suffix(path, READERS, "input")
    if not path.is_file():
        raise TreegenError(f"{path}: no such file")
    return READERS[path.suffix.lower()](path, lod, refuse_forest)


def save_still(pixels: np.ndarray, path: str | os.PathLike, colors: int = 0) -> Path:
    path = check_suffix(path, STILLS, "image")
    _write(lambda tmp: image.write_still(pixels, tmp, colors), path)
    return path


def save_loop(frames: list[np.ndarray], path: str | os.PathLike, duration: float) -> Path:
    """`frames` evenly spread over `duration` seconds, the closing pose left out."""
    path = check_suffix(path, LOOPS, "animation")
    _write(lambda tmp: image.write_loop(frames, tmp, duration), path)
    return path

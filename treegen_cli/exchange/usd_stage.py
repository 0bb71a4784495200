"""USD stages and files: a new stage's root prim, the up axis, writing a root layer to .usda,
.usdc or a reproducible .usdz, and the small encodings every USD writer shares (identifiers,
time codes). Tree (usd.py) and forest (forest_usd.py) writers alike.

Up axis: metres and right-handed either way. "Z" (the default of .usda/.usdc) writes generator
space as it is; "Y" (the default of .usdz: AR Quick Look needs it) changes axes with
axes.Z_UP_TO_Y_UP in every point, normal, matrix, quaternion and box (`Axes`), so the stage is
natively Y up with no hidden root transform.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from pathlib import Path

import numpy as np

from ..axes import matrix_to_y_up, quat_to_y_up, to_y_up
from ..errors import TreegenError

SUFFIXES = (".usda", ".usdc", ".usdz")


USDZ_MTIME = 946684800  # 2000-01-01: fixed zip entry time for reproducible .usdz bytes


def up_axis(requested: str | None, suffix: str) -> str:
    """ "Y" or "Z": the requested axis, else Y for a .usdz (AR Quick Look accepts only Y up)
    and Z (generator space, no conversion) for .usda/.usdc."""
    if requested is None:
        return "Y" if suffix == ".usdz" else "Z"
    up = str(requested).upper()
    if up not in ("Y", "Z"):
        raise TreegenError(f"up axis {requested!r}: expected y or z")
    return up


def check_suffix(path) -> str:
    """The lower-case USD suffix of `path`, or a TreegenError naming the allowed ones."""
    suffix = Path(path).suffix.lower()
    if suffix not in SUFFIXES:
        raise TreegenError(f"{path}: unknown USD extension {suffix!r}; allowed {', '.join(SUFFIXES)}")
    return suffix


def write_stage(stage, path, inner_name: str, files: dict[str, bytes] | None = None) -> None:
    """Write a stage's root layer to exactly `path`: .usda text, .usdc crate, or a .usdz
    package whose first entry `inner_name` is the crate (the root layer must come first).

    files: relative name → bytes of the files the layer refers to (textures): written beside
    `path`, or packaged after the layer in name order."""
    from pxr import Sdf

    path = Path(path)
    suffix = check_suffix(path)
    layer = stage.GetRootLayer()
    files = files or {}
    if suffix in (".usda", ".usdc"):
        if not layer.Export(str(path), args={"format": suffix[1:]}):
            raise TreegenError(f"{path}: could not write the USD layer")
        for name, data in sorted(files.items()):
            (path.parent / name).write_bytes(data)
        return
    tmpdir = tempfile.mkdtemp(prefix="treegen-usdz-", dir=path.parent if path.parent.exists() else None)
    try:
        inner = os.path.join(tmpdir, inner_name)
        if not layer.Export(inner, args={"format": "usdc"}):
            raise TreegenError(f"{path}: could not write the USD layer")
        entries = [(inner, inner_name)]
        for name, data in sorted(files.items()):
            local = os.path.join(tmpdir, "files", name)
            os.makedirs(os.path.dirname(local), exist_ok=True)
            with open(local, "wb") as f:
                f.write(data)
            entries.append((local, name))
        writer = Sdf.ZipFileWriter.CreateNew(str(path))
        for local, name in entries:
            # a zip entry carries the file's mtime: pin it so the same stage gives the same bytes
            os.utime(local, (USDZ_MTIME, USDZ_MTIME))
            writer.AddFile(local, name)
        if not writer.Save():
            raise TreegenError(f"{path}: could not write the usdz package")
    finally:
        shutil.rmtree(tmpdir, ignore_errors=True)


def new_stage(name: str, documentation: str, kind, up: str = "Z"):
    """An in-memory stage (metres, up axis `up`) whose default prim is an Xform named after
    `name` with model kind `kind`; returns (stage, root path)."""
    from pxr import Sdf, Usd, UsdGeom

    stage = Usd.Stage.CreateInMemory()
    stage.GetRootLayer().documentation = documentation
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y if up == "Y" else UsdGeom.Tokens.z)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    root_path = Sdf.Path("/" + identifier(name))
    root = UsdGeom.Xform.Define(stage, root_path).GetPrim()
    Usd.ModelAPI(root).SetKind(kind)
    stage.SetDefaultPrim(root)
    return stage, root_path


class Axes:
    """Generator space (Z up) → the stage's axes: identity for "Z" (values pass through
    untouched, so Z-up files keep their bytes), axes.Z_UP_TO_Y_UP for "Y"."""

    def __init__(self, up: str = "Z"):
        self.up = up
        self.y = up == "Y"

    def points(self, v: np.ndarray) -> np.ndarray:
        return to_y_up(v) if self.y else v

    def matrices(self, m: np.ndarray) -> np.ndarray:
        return matrix_to_y_up(m) if self.y else m

    def quats(self, q: np.ndarray) -> np.ndarray:
        return quat_to_y_up(q) if self.y else q

    def box(self, lo, hi) -> tuple[np.ndarray, np.ndarray]:
        """An axis-aligned box stays one: C permutes axes and flips signs."""
        if not self.y:
            return lo, hi
        a, b = to_y_up(np.asarray(lo, np.float64)), to_y_up(np.asarray(hi, np.float64))
        return np.minimum(a, b), np.maximum(a, b)


def sample_rate(times: np.ndarray) -> float:
    """Keys per second of a uniformly sampled clip (snapped to an integer when it is one)."""
    times = np.asarray(times, np.float64)
    if len(times) < 2 or times[-1] <= times[0]:
        return 24.0
    rate = (len(times) - 1) / (times[-1] - times[0])
    return float(round(rate)) if abs(rate - round(rate)) < 1e-6 else float(rate)


def snap(codes: np.ndarray) -> np.ndarray:
    """Round time codes that are integers up to float noise, so files carry clean frames."""
    r = np.round(codes)
    return np.where(np.abs(codes - r) < 1e-6, r, codes)


def gf_vec3f(v):
    from pxr import Gf

    return Gf.Vec3f(*(float(x) for x in v))


def identifier(name: str) -> str:
    """A prim name every USD reader takes: ASCII (accents dropped, `palmé` → `palme`, where
    Tf.MakeValidIdentifier alone makes `palm__` of its two UTF-8 bytes; readers before USD
    24.03 refuse UTF-8 names), other characters as underscores, a leading digit kept behind
    one (`123tree` → `_123tree`)."""
    import unicodedata

    from pxr import Tf

    plain = unicodedata.normalize("NFKD", name or "").encode("ascii", "ignore").decode("ascii")
    plain = plain or name or "tree"
    if plain[0].isdigit():  # (MakeValidIdentifier replaces the digit: 123tree → _23tree)
        plain = "_" + plain
    return Tf.MakeValidIdentifier(plain)


def unique(name: str, used: set[str]) -> str:
    out, k = name, 1
    while out in used:
        out, k = f"{name}_{k}", k + 1
    used.add(out)
    return out

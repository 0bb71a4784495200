"""Where the textures of a written file go, one rule for every format that keeps them as
separate files (USD, OBJ, a .gltf's images):

- inside a package (.usdz): `textures/<name>.png`;
- beside the main file: flat siblings `<stem>_<ext>_<name>.png` (`a.usdc` → `a_usdc_leaf.png`;
  flat, because staging moves the files a writer produced into place). The prefix is the whole
  output name, extension included, as no two outputs in one folder share it: `a.usdc` and
  `a.obj` (or `a.usda`) in one folder each keep their own textures.

Names come from Texture.name (made file- and identifier-safe); a texture used twice is written
once; two different textures with one name get `_1`, `_2`, ... in the order they are met, so
names depend only on the asset and the output name.
"""

from __future__ import annotations

import re
from pathlib import Path

from ..asset import Texture


def safe_name(name: str) -> str:
    """Letters, digits and `_` only, not starting with a digit (also a valid USD identifier)."""
    out = re.sub(r"[^A-Za-z0-9_]", "_", name) or "texture"
    return "_" + out if out[0].isdigit() else out


class TextureFiles:
    """Names the PNG files of the textures a file uses and collects their bytes (`files`:
    relative name → PNG bytes, for the writer to write or package)."""

    def __init__(self, path, packaged: bool | None = None):
        path = Path(path)
        self.packaged = path.suffix.lower() == ".usdz" if packaged is None else packaged
        # the whole output name with its dot made `_` (its stem alone if it has no extension)
        self.prefix = path.stem + path.suffix.replace(".", "_", 1)
        self.files: dict[str, bytes] = {}  # what this file uses
        self._all: dict[str, bytes] = {}  # every name given (shared views: all files')
        self._names: dict[Texture, str] = {}

    def shared(self) -> TextureFiles:
        """Names for one more file written beside the same textures (`--lod-files` parts): a
        texture keeps the name it has in every file that uses it, and `files` holds only
        what that file uses (each part writes the same bytes under the same names, once)."""
        view = TextureFiles.__new__(TextureFiles)
        view.packaged, view.prefix = self.packaged, self.prefix
        view.files, view._all, view._names = {}, self._all, self._names
        return view

    def name(self, texture: Texture, prefix: str = "") -> str:
        """The file's name relative to the main file ("textures/leaf.png", "tree_usdc_leaf.png")."""
        if texture not in self._names:
            base = safe_name(prefix + texture.name)
            base = f"textures/{base}" if self.packaged else f"{self.prefix}_{base}"
            name, k = base, 1
            while name + ".png" in self._all:
                name, k = f"{base}_{k}", k + 1
            self._all[name + ".png"] = texture.png
            self._names[texture] = name + ".png"
        name = self._names[texture]
        self.files[name] = self._all[name]
        return name

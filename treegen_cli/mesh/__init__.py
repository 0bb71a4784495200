"""Tree + Rig → skinned triangle lists: bark tubes along every stem and a card per leaf.

Result: one "bark" primitive (bark.py: a tube per stem, closed at its tip), a far LOD's "twigs"
(ribbons.py: its thin branches as crossed ribbons) and one "leaves" primitive (leaves.py: a
card or the LeafShape outline per leaf), all bound to the rig's joints;
options.py holds MeshOptions and the per-stem rules the size estimate shares.

    prims = build_mesh(tree, rig, MeshOptions(sides=(24, 10, 6, 4)))

Everything is ragged-array arithmetic over all stems at once (np.repeat / cumsum): no Python loop
over stems, rings, leaves or vertices (only over the few trunk stems for their flare rings).
"""

from __future__ import annotations

from ..asset import TWIGS, Primitive
from .bark import BARK_MAX_TILES, bark_offsets, bark_primitives
from .influences import merge_influences
from .leaves import CARD, leaf_variants, stamp_leaves
from .options import (
    FULL_CARD_CELL,
    LEAF_GEOMETRIES,
    MESH_DEFAULTS,
    MeshOptions,
    check_options,
    girth,
    pointed_tips,
    stem_sides,
)
from .ribbons import ribbons_as_tubes

__all__ = [
    "BARK_MAX_TILES",
    "CARD",
    "FULL_CARD_CELL",
    "LEAF_GEOMETRIES",
    "MESH_DEFAULTS",
    "TWIGS",
    "MeshOptions",
    "bark_offsets",
    "build_mesh",
    "girth",
    "leaf_variants",
    "merge_influences",
    "pointed_tips",
    "ribbons_as_tubes",
    "stem_sides",
]


def build_mesh(tree, rig, options: MeshOptions = MESH_DEFAULTS) -> list[Primitive]:
    """Bark (always) and leaves (when the tree has any and options.leaves), skinned to `rig`."""
    check_options(options)
    prims = bark_primitives(tree, rig, options)
    if options.leaves and tree.n_leaves:
        prims.append(stamp_leaves(tree, rig, options.leaf_geometry, options.leaf_cells))
    return prims

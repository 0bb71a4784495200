"""Weber–Penn: Params + seed → Tree, all of it as numpy arrays.

The model is recursive (a stem's children depend on its grown shape), but every stem of one
level shares the same `curve_res`, so a whole level grows at once: the loop runs over levels
and over segment indices, and each step updates all stems of the level as numpy arrays.

`generate` (grow.py) reads top to bottom; its steps, one module each:

- bounds.py — GenerateOptions, the count estimate and the refusals of oversized trees
- placement.py — the trunks, and each level's children along their parents
- stems.py — one level grown segment by segment (curve, helix, attraction up)
- splits.py — splits ("clones") at a node, with the declination correction
- prune.py — PruneRatio: stems shortened to fit the envelope
- radius.py — base radii, taper and flare
- leaves.py — leaf counts, places and blade frames (whorls, fans, LeafBend)
- regrow.py — geometric LODs: leaves regrown on a kept tree
- frames.py, draws.py — batched rotations; the seeded random streams and error diffusion
"""

from __future__ import annotations

from .bounds import DEFAULTS, GenerateOptions, check_size, check_trunk, estimate_counts
from .draws import error_diffuse
from .grow import generate
from .regrow import regrow_leaves

__all__ = [
    "DEFAULTS",
    "GenerateOptions",
    "check_size",
    "check_trunk",
    "error_diffuse",
    "estimate_counts",
    "generate",
    "regrow_leaves",
]

"""Triangle budgets per bundled species: the species' own LOD0 triangles, the plan's time and
levers, and the triangles LOD0 really has when built (bark + leaves from build_mesh).

    python bench/budget_bench.py                 # --triangles 20000 on every species
    python bench/budget_bench.py 50000 weeping_willow quaking_aspen
"""

from __future__ import annotations

import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from treegen_cli.budget import BudgetOptions, plan_budget  # noqa: E402
from treegen_cli.errors import TreegenError  # noqa: E402
from treegen_cli.generate import generate  # noqa: E402
from treegen_cli.limits import estimate_triangles  # noqa: E402
from treegen_cli.mesh import MESH_DEFAULTS, build_mesh  # noqa: E402
from treegen_cli.params import load_params  # noqa: E402
from treegen_cli.rig import build_rig  # noqa: E402


def main(argv: list[str]) -> None:
    budget = int(argv[0]) if argv else 20_000
    names = argv[1:] or sorted(p.stem for p in (ROOT / "species").glob("*.txt"))
    print(f"--triangles {budget:,}")
    print(f"{'species':<20}{'own':>11}{'plan s':>8}{'built':>9}{'off %':>7}  levers")
    offs = []
    for name in names:
        params = load_params(ROOT / "species" / f"{name}.txt")
        own = sum(estimate_triangles(generate(params, 0), MESH_DEFAULTS))
        t0 = time.perf_counter()
        try:
            plan = plan_budget(params, 0, MESH_DEFAULTS, BudgetOptions(triangles=budget))
        except TreegenError as e:
            print(f"{name:<20}{own:>11,}{time.perf_counter() - t0:>8.2f}  refused: {e}")
            continue
        seconds = time.perf_counter() - t0
        tree = generate(plan.params, 0)
        built = sum(len(p.indices) // 3 for p in build_mesh(tree, build_rig(tree), plan.mesh))
        off = 100.0 * (built - budget) / budget
        offs.append(abs(off))
        print(
            f"{name:<20}{own:>11,}{seconds:>8.2f}{built:>9,}{off:>7.2f}  "
            f"{plan.levels} levels, CurveRes ×{plan.curve_scale:g}, sides "
            f"{','.join(map(str, plan.mesh.sides))}, LeafQuality ×{plan.leaf_factor:.3g}"
        )
    if offs:
        print(f"median |off| {statistics.median(offs):.2f} %, max {max(offs):.2f} %")


if __name__ == "__main__":
    main(sys.argv[1:])

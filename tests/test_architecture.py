"""The package's shape: data flows one way. No import cycles between treegen_cli modules (at
module level or inside functions), and writers import nothing from the stages but the Asset
types and small helpers."""

from __future__ import annotations

import ast
from pathlib import Path

PKG = Path(__file__).resolve().parents[1] / "treegen_cli"


def module_name(path: Path) -> str:
    rel = path.relative_to(PKG.parent).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def imports(path: Path) -> set[str]:
    """treegen_cli modules `path` imports, anywhere in the file (relative imports resolved)."""
    me = module_name(path)
    package = me if path.name == "__init__.py" else me.rpartition(".")[0]
    out = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[: len(base) - node.level + 1]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            names = [target] + [f"{target}.{a.name}" for a in node.names]
        elif isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        else:
            continue
        out |= {n for n in names if n.startswith("treegen_cli")}
    return out


def graph() -> dict[str, set[str]]:
    files = {module_name(p): p for p in PKG.rglob("*.py")}
    g = {}
    for name, path in files.items():
        # "from . import x" names a module when x is one; otherwise the package itself
        g[name] = {t for t in imports(path) if t in files and t != name}
    return g


def cycles(g: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan)."""
    index, low, stack, on, out, counter = {}, {}, [], set(), [], [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in sorted(g[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(g):
        if v not in index:
            visit(v)
    return out


def test_cycle_finder_finds_a_cycle():
    assert cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]


def test_no_import_cycles():
    assert cycles(graph()) == []


WRITERS = [
    "exchange.gltf",
    "exchange.gltf_animation",
    "exchange.gltf_buffer",
    "exchange.gltf_container",
    "exchange.gltf_material",
    "exchange.gltf_mesh",
    "exchange.gltf_nodes",
    "exchange.usd",
    "exchange.usd_material",
    "exchange.usd_skel",
    "exchange.usd_stage",
    "exchange.forest_gltf",
    "exchange.forest_usd",
    "exchange.static",
    "exchange.image",
]
# what a writer may use: the Asset types, errors, the version, axis and quaternion helpers,
# and its sibling encoders
ALLOWED = {"treegen_cli", "treegen_cli.asset", "treegen_cli.errors", "treegen_cli.axes", "treegen_cli.quat"}


def test_writers_import_only_asset_types_and_helpers():
    """Through their sibling encoders too: a writer's helper in exchange/ that imported a
    stage (as the compressed files' key planning first did) would make the writer compute."""
    g = graph()
    for w in WRITERS:
        seen, todo = set(), [f"treegen_cli.{w}"]
        while todo:  # the writer and every exchange module it reaches
            name = todo.pop()
            if name in seen:
                continue
            seen.add(name)
            for t in g[name]:
                if t.startswith("treegen_cli.exchange."):
                    todo.append(t)
                elif t not in ALLOWED and t != "treegen_cli.exchange":
                    raise AssertionError(f"{name} (used by {w}) imports stage {t}")


# What a command may import: the API and the option table, the front doors of the jobs that
# are not one tree (batch, forest via api, preview, species list), and the CLI plumbing.
COMMAND_ALLOWED = {
    "treegen_cli",
    "treegen_cli.api",
    "treegen_cli.options",
    "treegen_cli.errors",
    "treegen_cli.progress",
    "treegen_cli.batch",
    "treegen_cli.executor",
    "treegen_cli.preview",
    "treegen_cli.species_list",
    "treegen_cli.bundled",
}


def test_commands_import_the_api_not_the_stages():
    g = graph()
    commands = [m for m in g if m.startswith("treegen_cli.commands.")]
    assert {"treegen_cli.commands.make", "treegen_cli.commands.info"} <= set(commands)
    for name in commands:
        bad = {t for t in g[name] if t not in COMMAND_ALLOWED and not t.startswith("treegen_cli.commands")}
        assert not bad, f"{name} imports {sorted(bad)}; go through api/options"


def test_every_make_option_is_one_click_option_with_the_table_default():
    """flags.py builds `make`'s options from options.DEFAULTS: none missing, none extra,
    no default typed twice."""
    from treegen_cli.commands.make import make
    from treegen_cli.options import DEFAULTS

    params = {
        p.name: p for p in make.params if p.name not in ("species", "output", "as_json", "quiet", "verbose")
    }
    assert set(params) == set(DEFAULTS)
    assert {k: p.default for k, p in params.items()} == DEFAULTS


# Every module fits one screenful of purpose (issue 11), or its docstring says why not.
SMALL = ["*.py", "*/*.py"]


def test_split_modules_stay_under_400_lines_or_say_why():
    for pattern in SMALL:
        for path in PKG.glob(pattern):
            text = path.read_text()
            doc = ast.get_docstring(ast.parse(text)) or ""
            n = text.count("\n")
            assert n <= 400 or "400 lines" in doc, (
                f"{path.relative_to(PKG)}: {n} lines; split it or say why in its docstring"
            )


def test_readme_module_list_names_every_module():
    """The README's module list is how a newcomer finds a job's module: a module it does not
    name (by file, or by its package folder) is missing there, and a name it gives that no
    longer exists is stale."""
    import re

    text = (PKG.parent / "README.md").read_text()
    section = text[text.index("One direction, one module per job") : text.index("## Gallery")]
    missing = [
        str(p.relative_to(PKG))
        for p in sorted(PKG.rglob("*.py"))
        if p.stem not in ("__init__", "__main__")
        and f"`{p.name}`" not in section
        and f"{p.name}" not in section
        and f"`{p.parent.name}/`" not in section
    ]
    assert not missing, f"README's module list does not name {missing}"
    named = set(re.findall(r"`([a-z_]+\.py)`", section))
    files = {p.name for p in PKG.rglob("*.py")}
    assert named <= files, f"README names modules that do not exist: {sorted(named - files)}"


def test_the_cli_starts_without_scipys_slow_parts_and_limits_every_blas():
    """Loading the CLI (every `treegen` call, `--help` included) imports no scipy.spatial or
    ndimage (the stages import them where used), but scipy.linalg it does: wind.one_blas_thread
    can only limit the BLAS libraries loaded when wind.py scans them, and scipy's own
    OpenBLAS, loaded later, ran LAPACK on every core (the palm's and sassafras's bytes moved)."""
    import subprocess
    import sys

    code = (
        "import sys, treegen_cli.cli; from treegen_cli.wind import _BLAS; "
        "print(sorted(m for m in sys.modules if m.split('.')[0] in {'moderngl', 'pxr', 'dask'} "
        "or m.startswith(('scipy.spatial', 'scipy.ndimage')))); "
        "print(sorted({c.filepath.split('site-packages')[-1].split('/')[1] for c in _BLAS.lib_controllers}))"
        "; from treegen_cli.wind import one_blas_thread; "
        "print(one_blas_thread(lambda: sorted({c.num_threads for c in _BLAS.lib_controllers}))())"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=PKG.parent
    )
    loaded, blas, threads = out.stdout.strip().splitlines()
    assert loaded == "[]", loaded
    assert "scipy.libs" in blas and "numpy.libs" in blas, blas
    assert threads == "[1]", threads  # both limited to one thread inside one_blas_thread

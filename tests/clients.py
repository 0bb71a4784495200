"""Real glTF clients nobody on the project wrote: what they see when they import our GLBs.

    godot_import(path, timeout=120) -> dict   Godot 3.2 editor import (headless server build) + inspect.gd
    godot_import_many(paths) -> {path: dict}  the same for many files in one project (one import run)
    three_load(path, timeout=120) -> dict     three.js GLTFLoader + AnimationMixer in Node (tools/three_check.mjs)
    babylon_load(path, timeout=120, container=False) -> dict
                                              Babylon.js NullEngine + glTF loader (tools/babylon_check.mjs)
    sibling_layout(glb_in, glb_out) -> int    rewrite a GLB so each skinned mesh node and its skeleton
                                              root joint are siblings (Blender's layout); for experiments

A missing client raises ClientMissing whose message names the install command; tests turn it into
a skip. Nothing here imports treegen_cli: the clients only ever see the files.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import signal
import struct
import subprocess
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
TOOLS = REPO / "tools"
GODOT = os.environ.get("TREEGEN_GODOT", "godot3-server")
NODE = os.environ.get("TREEGEN_NODE", "node")

GODOT_INSTALL = "godot3-server not installed: run make install (apt-get install godot3-server)"
NPM_INSTALL = "{what} not installed: run make install (cd tools && npm ci)"


class ClientMissing(RuntimeError):
    """The client program is not installed; the message says how to install it."""


# ---------------------------------------------------------------------------------------------
# process helpers


def _run(cmd, *, cwd=None, env=None, timeout):
    """Run cmd in its own process group; on timeout kill the whole group.
    -> (returncode or None on timeout, stdout, stderr, seconds)"""
    t0 = time.monotonic()
    proc = subprocess.Popen(
        cmd,
        cwd=cwd,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        errors="replace",
        start_new_session=True,
    )
    try:
        out, err = proc.communicate(timeout=timeout)
        return proc.returncode, out, err, time.monotonic() - t0
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        out, err = proc.communicate()
        return None, out, err, time.monotonic() - t0


# ---------------------------------------------------------------------------------------------
# Godot 3.2

_PROJECT = """; Engine configuration file (treegen test harness).
config_version=4

[application]
config/name="treegen_import_probe"
"""

# Import options for res://x.glb, written before the first import (Godot keeps them). Everything is
# Godot's default except materials/storage: with the default (1, "Files") the editor writes
# bark.material/leaf.material and then waits for thumbnails of them, which the server build's dummy
# renderer never draws -- the editor then never quits, for any file with materials.
_IMPORT_PRESET = """[remap]

importer="scene"

[params]

materials/storage=0
"""

# Lines the server build prints for every run, whatever the file: not about our files.
_GODOT_NOISE = (
    re.compile(r'free_static: Condition "p_ptr == __null" is true'),
    re.compile(r"get_language_code: Invalid locale"),
    re.compile(r"set_locale: Unsupported locale"),
    # MeshInstance asks the dummy rasterizer about meshes it never created
    re.compile(r'getornull: Condition "!id_map.has\(p_rid.get_data\(\)\)" is true'),
    re.compile(r'mesh_get_(surface|blend_shape)_count: Condition "!m" is true'),
)

_godot_version = None


def _godot_literal(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, str):
        return json.dumps(v)
    return repr(v)


def godot_version() -> str:
    global _godot_version
    if _godot_version is None:
        if shutil.which(GODOT) is None:
            raise ClientMissing(GODOT_INSTALL)
        _, out, _, _ = _run([GODOT, "--version"], timeout=30)
        _godot_version = out.strip().splitlines()[-1] if out.strip() else "?"
    return _godot_version


def _tail(text: str, n: int = 30) -> list[str]:
    """The last n lines of Godot output that are not server-build noise (for failure reports)."""
    keep = [
        ln
        for ln in text.splitlines()
        if ln.strip()
        and not any(p.search(ln) for p in _GODOT_NOISE)
        and not ln.strip().startswith("At: core/os/memory.cpp")
    ]
    return keep[-n:]


def _godot_messages(stderr: str, phase: str, noise: dict) -> list[dict]:
    """ERROR:/WARNING: lines (with their 'At:' line) -> [{phase, level, message, at, count}]."""
    found: dict[tuple, dict] = {}
    lines = stderr.splitlines()
    for i, line in enumerate(lines):
        m = re.match(r"\s*(ERROR|WARNING|SCRIPT ERROR): (.*)", line)
        if not m:
            continue
        level, text = m.group(1), m.group(2).strip()
        at = ""
        if i + 1 < len(lines) and lines[i + 1].strip().startswith("At:"):
            at = lines[i + 1].strip()[3:].strip()
        if any(p.search(text) for p in _GODOT_NOISE):
            noise[text] = noise.get(text, 0) + 1
            continue
        key = (level, text, at)
        if key in found:
            found[key]["count"] += 1
        else:
            found[key] = {"phase": phase, "level": level, "message": text, "at": at, "count": 1}
    return list(found.values())


def _project(tmp: Path) -> tuple[Path, dict]:
    """A fresh Godot project (with inspect.gd) under `tmp`, and an environment whose config,
    data and cache folders live there too (nothing leaks into the user's Godot settings)."""
    proj = tmp / "project"
    proj.mkdir()
    (proj / "project.godot").write_text(_PROJECT)
    shutil.copyfile(TOOLS / "godot" / "inspect.gd", proj / "inspect.gd")
    env = dict(
        os.environ,
        LANG="en_US.UTF-8",
        XDG_CONFIG_HOME=str(tmp / "config"),
        XDG_DATA_HOME=str(tmp / "data"),
        XDG_CACHE_HOME=str(tmp / "cache"),
    )
    return proj, env


def _inspect(proj: Path, env: dict, scene: str, result: dict, timeout: float) -> None:
    """Run inspect.gd on the imported `scene` and merge its report into `result`."""
    rc, out, err, secs = _run(
        [GODOT, "--path", str(proj), "-s", "res://inspect.gd", f"--scene={scene}"], env=env, timeout=timeout
    )
    result["inspect_seconds"] = round(secs, 2)
    result["errors"] += _godot_messages(err, "inspect", result["noise"])
    line = next((ln for ln in out.splitlines() if ln.startswith("TREEGEN_JSON ")), None)
    if line is None:
        result["reason"] = "inspect: timeout" if rc is None else f"inspect: no output (exit {rc})"
        result["log_tail"] = _tail(out + err)
        return
    report = json.loads(line[len("TREEGEN_JSON ") :])
    result.update({k: v for k, v in report.items() if k != "scene"})
    result["imported"] = bool(report.get("loaded"))
    if not result["imported"]:
        result["reason"] = report.get("reason", "not loaded")


def godot_import(
    glb_path, timeout: float = 120, *, options: dict | None = None, keep_project: str | None = None
) -> dict:
    """Import glb_path the way the Godot 3.2 editor does, then load and inspect the imported scene.

    Import: a fresh project with project.godot and the file as res://x.glb (res://x.gltf with
    the .bin and PNGs it names beside it), then
    `godot3-server --path PROJECT --editor --quit` (the editor's first scan imports every new file
    before it quits). Inspect: `godot3-server --path PROJECT -s res://inspect.gd` loads res://x.glb,
    instances it inside the SceneTree and prints one JSON line (tools/godot/inspect.gd).

    -> {"client": "godot", "version", "file", "imported": bool, "reason": None | "timeout" | ...,
        "import_seconds", "import_exit": returncode or "timeout", "log_tail" (on failure),
        "errors": [{"phase": "import"|"inspect", "level", "message", "at", "count"}],
        "noise": {message: count} (server-build lines printed for any file),
        and when imported, what inspect.gd reports: "loaded", "load_ms", "inspect_seconds",
        "nodes": [{name, type, parent}], "skeletons": [{path, bone_count, root_bones, first_bones}],
        "mesh_instances": [{path, skeleton, skeleton_found, skin_binds, surfaces: [{vertices,
            has_normal, zero_normals, has_uv, uv_min, uv_max, has_bones, bone_index_max,
            material: {name, type, albedo_texture, normal_texture, albedo_color, transparent,
            alpha_scissor, alpha_scissor_threshold, cull_mode}}]}],
        "animation_players": [{path, animations: [{name, length, tracks, tracks_resolved, keys_max, loop,
            sample_times, bones_moved, max_local_change, max_global_change, loop_max_diff,
            loop_closes}]}]}
    options: extra import options for x.glb.import's [params], e.g. {"skins/use_named_skins": False}
    (values written as Godot literals: bool -> true/false, str quoted, numbers as is).
    keep_project: copy the project directory there afterwards (debugging).
    """
    version = godot_version()
    glb_path = Path(glb_path)
    if not glb_path.is_file():
        raise FileNotFoundError(glb_path)
    result: dict = {
        "client": "godot",
        "version": version,
        "file": str(glb_path),
        "imported": False,
        "reason": None,
        "errors": [],
        "noise": {},
    }
    with tempfile.TemporaryDirectory(prefix="treegen_godot_") as tmp:
        proj, env = _project(Path(tmp))
        x = "x" + glb_path.suffix.lower()  # a .gltf comes with the files it names
        shutil.copyfile(glb_path, proj / x)
        for name in _sibling_files(glb_path):
            shutil.copyfile(glb_path.parent / name, proj / name)
        (proj / f"{x}.import").write_text(
            _IMPORT_PRESET + "".join(f"{k}={_godot_literal(v)}\n" for k, v in (options or {}).items())
        )

        rc, _, err, secs = _run([GODOT, "--path", str(proj), "--editor", "--quit"], env=env, timeout=timeout)
        result["import_seconds"] = round(secs, 2)
        result["import_exit"] = "timeout" if rc is None else rc
        result["errors"] += _godot_messages(err, "import", result["noise"])
        scn = list((proj / ".import").glob(f"{x}-*.scn")) if (proj / ".import").is_dir() else []
        if not scn:
            result["reason"] = "timeout" if rc is None else f"no imported scene (exit {rc})"
            result["log_tail"] = _tail(err)
        else:
            if rc is None:
                result["reason"] = "imported, but the editor did not exit before the timeout"
            _inspect(proj, env, f"res://{x}", result, timeout)
        if keep_project:
            shutil.copytree(proj, keep_project, dirs_exist_ok=True)
    return result


def _sibling_files(path: Path) -> list[str]:
    """The files a .gltf names by relative URI (its buffers, its images); none for a .glb."""
    if path.suffix.lower() != ".gltf":
        return []
    from urllib.parse import unquote

    doc = json.loads(path.read_text(encoding="utf-8"))
    uris = [b.get("uri", "") for b in doc.get("buffers", [])] + [
        i.get("uri", "") for i in doc.get("images", [])
    ]
    return [unquote(u) for u in uris if u and not u.startswith("data:")]


def godot_import_many(glb_paths, timeout: float = 600, *, inspect_timeout: float = 120) -> dict:
    """Import many GLBs in one Godot project (one editor run: Godot's start-up is paid once),
    then inspect each: {path: report} with the same keys as godot_import's, where
    "import_seconds" is the whole batch's import time."""
    version = godot_version()
    paths = [Path(p) for p in glb_paths]
    results: dict = {}
    with tempfile.TemporaryDirectory(prefix="treegen_godot_") as tmp:
        proj, env = _project(Path(tmp))
        names = {}
        for i, p in enumerate(paths):
            name = f"f{i:03d}_{p.stem}.glb"
            names[p] = name
            shutil.copyfile(p, proj / name)
            (proj / f"{name}.import").write_text(_IMPORT_PRESET)
        rc, _, err, secs = _run([GODOT, "--path", str(proj), "--editor", "--quit"], env=env, timeout=timeout)
        import_noise: dict = {}
        import_errors = _godot_messages(err, "import", import_noise)
        for p in paths:
            name = names[p]
            r: dict = {
                "client": "godot",
                "version": version,
                "file": str(p),
                "imported": False,
                "reason": None,
                "import_seconds": round(secs, 2),
                "import_exit": "timeout" if rc is None else rc,
                "errors": [e for e in import_errors if name in e["message"] or p.stem in e["message"]],
                "noise": {},
            }
            imp = proj / ".import"
            if not (imp.is_dir() and list(imp.glob(f"{name}-*.scn"))):
                r["reason"] = "timeout" if rc is None else f"no imported scene (exit {rc})"
                r["log_tail"] = _tail(err)
                results[str(p)] = r
                continue
            _inspect(proj, env, f"res://{name}", r, inspect_timeout)
            results[str(p)] = r
    return results


# ---------------------------------------------------------------------------------------------
# three.js and Babylon.js (Node)


def _node_client(script: str, package: str, what: str, glb_path, extra, timeout) -> dict:
    if shutil.which(NODE) is None or not (TOOLS / "node_modules" / package / "package.json").is_file():
        raise ClientMissing(NPM_INSTALL.format(what=what))
    glb_path = Path(glb_path).resolve()  # node runs in tools/
    if not glb_path.is_file():
        raise FileNotFoundError(glb_path)
    rc, out, err, secs = _run([NODE, str(TOOLS / script), *extra, str(glb_path)], cwd=TOOLS, timeout=timeout)
    if rc is None:
        return {
            "client": what,
            "file": str(glb_path),
            "loaded": False,
            "error": "timeout",
            "seconds": round(secs, 2),
        }
    lines = [ln for ln in out.splitlines() if ln.startswith("{")]
    if rc != 0 or not lines:
        return {
            "client": what,
            "file": str(glb_path),
            "loaded": False,
            "error": f"exit {rc}: {err.strip()[-2000:]}",
            "seconds": round(secs, 2),
        }
    report = json.loads(lines[-1])
    report["seconds"] = round(secs, 2)
    report["warnings"] = [m["text"] for m in report.get("messages", []) if m["level"] in ("warn", "error")]
    return report


def three_load(glb_path, timeout: float = 120, poses: int = 0, positions: bool = False) -> dict:
    """three.js r187 GLTFLoader.parse in Node (textures are stubbed: references, not pixels).

    -> {"client": "three.js", "version", "loaded", "error"?, "load_ms", "seconds", "nodes",
        "skeletons": [{bones, meshes}], "meshes": [{name, type, skinned, vertices, has_normal,
        uv: {min, max, normalized, array}, material}], "materials": [{name, type,
        base_color_texture, normal_texture, color, transparent, alpha_test, double_sided,
        flat_shading}], "animations": [{name, duration, tracks, sample_times, bones_moved,
        max_local_change, max_world_change, loop_max_diff, loop_closes, messages_while_playing}],
        "messages": [{level, text}] (all console output), "warnings": [text] (warn + error),
        "extensions_required"}; EXT_meshopt_compression through three's MeshoptDecoder.
    poses=K: animations[i].poses, every scene node's world position at K times (K × nodes × 3);
    positions: meshes[i].positions, the decoded POSITION values (flat), mesh space.
    """
    extra = (["--poses", str(poses)] if poses else []) + (["--positions"] if positions else [])
    return _node_client("three_check.mjs", "three", "three.js", glb_path, extra, timeout)


def babylon_load(glb_path, timeout: float = 120, container: bool = False) -> dict:
    """Babylon.js 9 (NullEngine) glTF loader: AppendSceneAsync, or LoadAssetContainerAsync +
    addAllToScene when container=True; waits for all MSFT_lod levels; renders one frame.

    -> {"client": "babylon.js", "version", "loaded", "error"?, "load_path", "load_ms", "seconds",
        "engine_caps", "msft_lod_levels_loaded", "nodes", "skeletons": [{name, bones, meshes}],
        "meshes": [{name, vertices, has_normal, uv: {min, max}, skinned, material}],
        "meshes_after_render": [{name, has_normal}], "messages_at_first_render",
        "materials": [{name, class, back_face_culling, base_color_texture, normal_texture,
        transparency_mode, alpha_cutoff}], "animations": [{name, from_frame, to_frame, fps,
        duration, targeted_animations, targets_disposed, sample_times, bones_moved,
        max_local_change, max_world_change, loop_max_diff, loop_closes}],
        "messages": [{level, text}], "warnings": [text]}
    """
    extra = ["--container"] if container else []
    return _node_client("babylon_check.mjs", "@babylonjs/loaders", "Babylon.js", glb_path, extra, timeout)


# ---------------------------------------------------------------------------------------------
# GLB surgery for experiments


def _read_glb(path):
    data = Path(path).read_bytes()
    magic, version, _ = struct.unpack_from("<III", data, 0)
    if magic != 0x46546C67 or version != 2:
        raise ValueError(f"{path}: not a GLB 2.0 file")
    n, kind = struct.unpack_from("<II", data, 12)
    if kind != 0x4E4F534A:
        raise ValueError(f"{path}: first chunk is not JSON")
    return json.loads(data[20 : 20 + n]), data[20 + n :]


def _write_glb(path, gltf, rest: bytes):
    js = json.dumps(gltf, separators=(",", ":")).encode()
    js += b" " * (-len(js) % 4)
    head = struct.pack("<III", 0x46546C67, 2, 12 + 8 + len(js) + len(rest))
    Path(path).write_bytes(head + struct.pack("<II", len(js), 0x4E4F534A) + js + rest)


def sibling_layout(glb_in, glb_out, wrap: bool = True) -> int:
    """Copy glb_in to glb_out with every skinned mesh node that is the parent of its skin's
    skeleton root made a sibling of it: the joint moves up to the mesh node's parent, or, for a
    node without a parent (a scene root or an MSFT_lod level), both go under a new node
    "<mesh>_root" that takes the mesh node's place in the scene; an MSFT_lod extension (and the
    MSFT_screencoverage extras) moves to that new node, its ids mapped to the levels' new nodes.
    wrap=False: a mesh node that is a scene root gets its joint as another scene root instead of a
    wrapper (glTF-Validator warns NODE_SKINNED_MESH_NON_ROOT about skinned meshes under one).
    Buffers are untouched. -> number of mesh nodes changed (0: already in sibling layout)."""
    gltf, rest = _read_glb(glb_in)
    nodes = gltf["nodes"]
    parent = {c: i for i, n in enumerate(nodes) for c in n.get("children", [])}
    wrapper_of = {}
    moved = 0
    for i in range(len(nodes)):
        node = nodes[i]
        if "skin" not in node:
            continue
        joint = gltf["skins"][node["skin"]].get("skeleton")
        if joint is None or joint not in node.get("children", []):
            continue
        node["children"].remove(joint)
        if not node["children"]:
            del node["children"]
        scenes = [sc for sc in gltf.get("scenes", []) if i in sc.get("nodes", [])]
        if i in parent:
            nodes[parent[i]]["children"].append(joint)
        elif not wrap and scenes:
            for sc in scenes:
                sc["nodes"].insert(sc["nodes"].index(i) + 1, joint)
        else:
            wrapper_of[i] = len(nodes)
            nodes.append({"name": f"{node.get('name', 'mesh')}_root", "children": [i, joint]})
            for scene in gltf.get("scenes", []):
                scene["nodes"] = [wrapper_of[i] if k == i else k for k in scene.get("nodes", [])]
        moved += 1
    for i, w in wrapper_of.items():
        lod = nodes[i].get("extensions", {}).pop("MSFT_lod", None)
        if lod is None:
            continue
        if not nodes[i]["extensions"]:
            del nodes[i]["extensions"]
        nodes[w]["extensions"] = {"MSFT_lod": dict(lod, ids=[wrapper_of.get(k, k) for k in lod["ids"]])}
        cover = nodes[i].get("extras", {}).pop("MSFT_screencoverage", None)
        if cover is not None:
            nodes[w]["extras"] = {"MSFT_screencoverage": cover}
            if not nodes[i]["extras"]:
                del nodes[i]["extras"]
    _write_glb(glb_out, gltf, rest)
    return moved


def main(argv=None) -> int:
    """python tests/clients.py FILE.glb [--client godot|three|babylon ...] [--siblings]: JSON per client."""
    import argparse

    ap = argparse.ArgumentParser(description=main.__doc__)
    ap.add_argument("glb")
    ap.add_argument("--client", action="append", choices=["godot", "three", "babylon"])
    ap.add_argument("--timeout", type=float, default=120)
    ap.add_argument(
        "--siblings", action="store_true", help="import a sibling_layout() copy instead of the file itself"
    )
    args = ap.parse_args(argv)
    glb = Path(args.glb)
    with tempfile.TemporaryDirectory() as tmp:
        if args.siblings:
            fixed = Path(tmp) / "siblings.glb"
            sibling_layout(glb, fixed)
            glb = fixed
        run = {"godot": godot_import, "three": three_load, "babylon": babylon_load}
        for name in args.client or ["three", "babylon", "godot"]:
            try:
                report = run[name](glb, timeout=args.timeout)
            except ClientMissing as exc:
                report = {"client": name, "missing": str(exc)}
            print(json.dumps(report))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

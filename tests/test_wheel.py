"""The project as a user installs it: a wheel built from this checkout, installed (not editable)
into a fresh virtual environment, run from an empty folder by a bundled species' name.

The venv sees the environment's pinned dependencies (--system-site-packages) so nothing is
downloaded at install time; `--no-index` makes pip prove the wheel's pins are met by them. The
test checks that the venv's own copy of treegen_cli is what runs, not this checkout or an
editable install elsewhere."""

from __future__ import annotations

import json
import os
import shutil
import struct
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def _run(args, **kw) -> subprocess.CompletedProcess:
    proc = subprocess.run([str(a) for a in args], capture_output=True, text=True, **kw)
    assert proc.returncode == 0, f"{' '.join(map(str, args))}\n{proc.stdout}\n{proc.stderr}"
    return proc


def _glb_chunks(path: Path) -> tuple[dict, int]:
    """The JSON chunk and BIN chunk length of a GLB, after checking its header and chunk table."""
    data = path.read_bytes()
    magic, version, length = struct.unpack_from("<4sII", data, 0)
    assert (magic, version, length) == (b"glTF", 2, len(data))
    json_len, json_type = struct.unpack_from("<II", data, 12)
    assert json_type == 0x4E4F534A and json_len % 4 == 0
    doc = json.loads(data[20 : 20 + json_len])
    bin_len, bin_type = struct.unpack_from("<II", data, 20 + json_len)
    assert bin_type == 0x004E4942 and 28 + json_len + bin_len == len(data)
    return doc, bin_len


def test_wheel_installs_into_a_fresh_venv_and_makes_a_tree_by_name(tmp_path):
    # build from a copy, so the checkout gets no build/ or *.egg-info
    src = tmp_path / "src"
    src.mkdir()
    shutil.copytree(
        ROOT / "treegen_cli", src / "treegen_cli", ignore=shutil.ignore_patterns("__pycache__", "*.pyc")
    )
    for name in ("pyproject.toml", "README.md"):
        shutil.copy(ROOT / name, src / name)
    dist = tmp_path / "dist"
    _run([sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", dist, src])
    (wheel,) = dist.glob("treegen-*.whl")

    venv = tmp_path / "venv"
    _run([sys.executable, "-m", "venv", "--system-site-packages", "--without-pip", venv])
    python = venv / "bin" / "python"
    _run([sys.executable, "-m", "pip", "--python", python, "install", "-q", "--no-index", wheel])

    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME")}
    env["PATH"] = f"{venv / 'bin'}{os.pathsep}{env.get('PATH', '')}"
    empty = tmp_path / "empty"
    empty.mkdir()
    where = _run(
        [
            python,
            "-c",
            "import treegen_cli, treegen_cli.bundled as b; "
            "print(treegen_cli.__file__); print(len(b.bundled_names()))",
        ],
        env=env,
        cwd=empty,
    )
    module, count = where.stdout.split()
    site = Path(
        _run(
            [python, "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"], env=env, cwd=empty
        ).stdout.strip()
    )
    assert Path(module).is_relative_to(site) and site.is_relative_to(venv)
    assert int(count) == len(list((ROOT / "treegen_cli" / "species").glob("*.txt")))

    _run([venv / "bin" / "treegen", "make", "quaking_aspen", "-o", "x.glb", "-q"], env=env, cwd=empty)
    assert sorted(p.name for p in empty.iterdir()) == ["x.glb", "x.glb.impostor.json"]
    doc, bin_len = _glb_chunks(empty / "x.glb")
    assert doc["asset"]["version"] == "2.0" and doc["buffers"][0]["byteLength"] <= bin_len
    assert doc["skins"] and doc["animations"][0]["name"] == "wind_loop"
    assert "MSFT_lod" in doc.get("extensionsUsed", [])  # the default 4 LODs

"""`treegen batch` as a studio meets it: a real Dask scheduler and two workers started with the
`dask` CLI as separate processes on 127.0.0.1, a 12-job catalogue, a worker killed mid-run,
reruns that skip, a changed option that rebuilds only its jobs, a failing entry reported by its
JSON path; the embedded LocalCluster the same way; catalogue errors exit 2 writing nothing.
Every output must be byte-identical to a serial `treegen make` of the same job."""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from conftest import DASK_ENV, dask_cluster

ROOT = Path(__file__).resolve().parent.parent
ENV = DASK_ENV  # this checkout importable, no inherited scheduler
CLIP = {"duration": 1, "fps": 10, "lod_distances": [0, 30]}

# 12 jobs, 10 trees: aspen 2 seeds × (glb, usdc); a small pair 2 seeds × a 2-value grid; rush 4 seeds
CATALOGUE = {
    "defaults": CLIP,
    "entries": [
        {"species": "species/quaking_aspen.txt", "seeds": "1-2", "formats": ["glb", "usdc"]},
        {"species": "species/pair_small.txt", "seeds": [3, 4], "grid": {"wind_speed": [2, 8]}},
        {"species": "species/rush.txt", "seeds": "5-8"},
    ],
}
OUTPUTS = [
    "quaking_aspen_1.glb",
    "quaking_aspen_1.usdc",
    "quaking_aspen_2.glb",
    "quaking_aspen_2.usdc",
    "pair_small_3_wind_speed-2.glb",
    "pair_small_4_wind_speed-2.glb",
    "pair_small_3_wind_speed-8.glb",
    "pair_small_4_wind_speed-8.glb",
    "rush_5.glb",
    "rush_6.glb",
    "rush_7.glb",
    "rush_8.glb",
]


def treegen(*args, env=None, cwd=None):
    return subprocess.run(
        [sys.executable, "-m", "treegen_cli", *map(str, args)],
        capture_output=True,
        text=True,
        env=env or ENV,
        cwd=cwd or ROOT,
    )


def events(stdout: str) -> list[dict]:
    return [json.loads(line) for line in stdout.splitlines() if line.startswith("{")]


@pytest.fixture(scope="module")
def workspace(tmp_path_factory) -> Path:
    """A catalogue folder with its own species files (paths are relative to the catalogue)."""
    root = tmp_path_factory.mktemp("batch")
    (root / "species").mkdir()
    for src in (
        ROOT / "species" / "quaking_aspen.txt",
        ROOT / "species" / "rush.txt",
        ROOT / "species" / "weeping_willow.txt",
        ROOT / "tests" / "fixtures" / "pair_small.txt",
    ):
        shutil.copy(src, root / "species" / src.name)
    (root / "catalogue.json").write_text(json.dumps(CATALOGUE, indent=1))
    (root / "images").mkdir()
    (root / "images" / "not.png").write_text("a text file named .png")
    _png(root / "images" / "leaf.png", (40, 160, 40, 255))
    return root


def _png(path: Path, rgba: tuple) -> None:
    from PIL import Image

    img = Image.new("RGBA", (8, 8), rgba)
    img.putpixel((0, 0), (0, 0, 0, 0))  # a leaf's cut-out (an opaque leaf image is refused)
    img.save(path)


@pytest.fixture(scope="module")
def serial(workspace) -> Path:
    """Every job of CATALOGUE made one by one with api.make (the path `treegen make` takes)."""
    from treegen_cli import api

    out = workspace / "serial"
    out.mkdir()
    sp = workspace / "species"
    for seed in (1, 2):
        for ext in ("glb", "usdc"):
            api.make(sp / "quaking_aspen.txt", out / f"quaking_aspen_{seed}.{ext}", seed=seed, **CLIP)
    for wind in (2, 8):
        for seed in (3, 4):
            api.make(
                sp / "pair_small.txt",
                out / f"pair_small_{seed}_wind_speed-{wind}.glb",
                seed=seed,
                wind_speed=wind,
                **CLIP,
            )
    for seed in (5, 6, 7, 8):
        api.make(sp / "rush.txt", out / f"rush_{seed}.glb", seed=seed, **CLIP)
    return out


@pytest.fixture(scope="module")
def cluster():
    """`dask scheduler` and two `dask worker`s importing this checkout's treegen_cli."""
    with dask_cluster(("w1", "w2")) as (address, workers):
        yield {"address": address, "workers": workers}


def assert_outputs(out: Path, serial: Path) -> None:
    for name in OUTPUTS:
        assert (out / name).read_bytes() == (serial / name).read_bytes(), name
    leftovers = [p.name for p in out.iterdir() if p.name.startswith(".")]
    assert leftovers == [], leftovers


# ----------------------------------------------------------------------------- on a Dask cluster


@pytest.fixture(scope="module")
def scheduler_run(workspace, cluster):
    """The first run through --scheduler; worker w2 is SIGKILLed after the first job is in."""
    out = workspace / "out"
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "treegen_cli",
            "batch",
            workspace / "catalogue.json",
            "-o",
            out,
            "--scheduler",
            cluster["address"],
            "--json",
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=ENV,
        cwd=workspace,
    )
    lines = []
    killed_after = None
    for line in proc.stdout:
        lines.append(line)
        if killed_after is None and '"event": "built"' in line:
            w2 = cluster["workers"]["w2"]
            os.killpg(w2.pid, signal.SIGKILL)
            w2.wait()
            killed_after = len(lines)
    proc.wait(timeout=120)
    return {
        "out": out,
        "rc": proc.returncode,
        "stderr": proc.stderr.read(),
        "events": events("".join(lines)),
        "killed_after": killed_after,
    }


def test_cluster_builds_every_job_byte_identical_despite_a_killed_worker(scheduler_run, serial):
    from treegen_cli.exchange.validate import validate_gltf

    run, out = scheduler_run, scheduler_run["out"]
    assert run["rc"] == 0, run["stderr"]
    assert run["killed_after"] is not None and run["killed_after"] < 12  # killed mid-run
    done = run["events"][-1]
    assert done["event"] == "done" and done["built"] == 12 and done["failed"] == 0, done
    assert_outputs(out, serial)
    for name in OUTPUTS:
        if name.endswith(".glb"):
            issues = validate_gltf((out / name).resolve())["issues"]
            assert issues["numErrors"] == 0 and issues["numWarnings"] == 0, name
    manifest = json.loads((out / "manifest.json").read_text())
    rows = {r["path"]: r for r in manifest["assets"]}
    assert sorted(rows) == sorted(OUTPUTS)
    r = rows["pair_small_4_wind_speed-8.glb"]
    assert r["entry"] == "entries[1]" and r["seed"] == 4 and r["grid"] == {"wind_speed": 8}
    assert r["files"] == [r["path"], r["path"] + ".impostor.json"] and r["status"] == "built"
    assert r["bytes"] == sum((out / f).stat().st_size for f in r["files"])
    assert len(r["triangles"]) == len(r["joints"]) == len(r["keys"]) == 3  # 2 LODs + impostor
    assert r["worker"].startswith("tcp://127.0.0.1:") and r["seconds"] > 0
    assert len({r["worker"] for r in rows.values()}) >= 1
    csv_lines = (out / "manifest.csv").read_text().splitlines()
    assert csv_lines[0].startswith("entry,species,seed,format,path,options_hash") and len(csv_lines) == 13


def test_a_serial_treegen_make_writes_the_same_bytes(scheduler_run, workspace, tmp_path):
    # same file name: a .usdc names its sibling textures after itself
    proc = treegen(
        "make",
        workspace / "species" / "quaking_aspen.txt",
        "-o",
        tmp_path / "quaking_aspen_2.usdc",
        "--seed",
        "2",
        "--duration",
        "1",
        "--fps",
        "10",
        "--lod-distances",
        "0,30",
        "-q",
    )
    assert proc.returncode == 0, proc.stderr
    for p in tmp_path.iterdir():
        assert p.read_bytes() == (scheduler_run["out"] / p.name).read_bytes(), p.name


def test_rerun_skips_every_job(scheduler_run, workspace, cluster):
    out = scheduler_run["out"]
    before = {n: (out / n).stat().st_mtime_ns for n in OUTPUTS}
    proc = treegen(
        "batch",
        workspace / "catalogue.json",
        "-o",
        out,
        "--json",
        env={**ENV, "DASK_SCHEDULER_ADDRESS": cluster["address"]},
    )
    assert proc.returncode == 0, proc.stderr
    done = events(proc.stdout)[-1]
    assert done["skipped"] == 12 and done["built"] == 0, done
    assert {n: (out / n).stat().st_mtime_ns for n in OUTPUTS} == before


def test_a_changed_option_rebuilds_only_its_jobs(scheduler_run, workspace, cluster, tmp_path):
    out = scheduler_run["out"]
    changed = json.loads(json.dumps(CATALOGUE))
    changed["entries"][1]["grid"]["wind_speed"] = [2, 9]
    cat = workspace / "changed.json"
    cat.write_text(json.dumps(changed))
    proc = treegen("batch", cat, "-o", out, "--scheduler", cluster["address"], "--json")
    assert proc.returncode == 0, proc.stderr
    built = sorted(e["path"] for e in events(proc.stdout) if e["event"] == "built")
    assert built == ["pair_small_3_wind_speed-9.glb", "pair_small_4_wind_speed-9.glb"]
    assert events(proc.stdout)[-1]["skipped"] == 10
    from treegen_cli import api

    api.make(workspace / "species" / "pair_small.txt", tmp_path / "p.glb", seed=3, wind_speed=9, **CLIP)
    assert (tmp_path / "p.glb").read_bytes() == (out / "pair_small_3_wind_speed-9.glb").read_bytes()


def test_a_failing_entry_is_reported_by_its_json_path_and_the_rest_complete(
    scheduler_run, workspace, cluster
):
    out = scheduler_run["out"]
    failing = json.loads(json.dumps(CATALOGUE))
    failing["entries"].append({"species": "species/weeping_willow.txt", "seeds": [1], "max_leaves": 1000})
    cat = workspace / "failing.json"
    cat.write_text(json.dumps(failing))
    proc = treegen("batch", cat, "-o", out, "--scheduler", cluster["address"], "--force", "--json")
    assert proc.returncode == 1, proc.stderr
    err = [line for line in proc.stderr.splitlines() if line.strip()]
    assert len(err) == 1 and "entries[3]" in err[0] and "seed 1" in err[0], err
    # the make option by the key that set it, not by make's flag
    assert "raise entries[3].max_leaves" in err[0] and "--max-leaves" not in err[0], err
    done = events(proc.stdout)[-1]
    assert done["built"] == 12 and done["failed"] == 1, done
    rows = {r["path"]: r for r in json.loads((out / "manifest.json").read_text())["assets"]}
    assert rows["weeping_willow_1.glb"]["status"] == "failed"
    assert "1,000" in rows["weeping_willow_1.glb"]["error"]
    assert not (out / "weeping_willow_1.glb").exists()


def test_a_cluster_whose_worker_lacks_this_treegen_is_refused_before_anything_is_written(
    scheduler_run, workspace, cluster, tmp_path
):
    fake = tmp_path / "fake"
    (fake / "treegen_cli").mkdir(parents=True)
    (fake / "treegen_cli" / "__init__.py").write_text('__version__ = "0.0.0"\n')
    worker = subprocess.Popen(
        [
            "dask",
            "worker",
            cluster["address"],
            "--nthreads",
            "1",
            "--name",
            "stale",
            "--host",
            "127.0.0.1",
            "--no-dashboard",
        ],
        env={**ENV, "PYTHONPATH": str(fake)},
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        start_new_session=True,
    )
    try:
        from distributed import Client

        with Client(cluster["address"], timeout="30s") as client:
            client.wait_for_workers(2, timeout=60)  # w1 and the stale one (w2 was killed)
        out = workspace / "refused"
        proc = treegen(
            "batch", workspace / "catalogue.json", "-o", out, "--force", "--scheduler", cluster["address"]
        )
        assert proc.returncode == 2, proc.stderr
        # refused either because the stale package cannot run a job or by its version
        assert ("cannot run treegen" in proc.stderr and "install treegen" in proc.stderr) or (
            "has treegen 0.0.0" in proc.stderr and "install the same version" in proc.stderr
        )
        assert len(proc.stderr.strip().splitlines()) == 1 and not out.exists()
    finally:
        os.killpg(worker.pid, signal.SIGKILL)
        worker.wait()


def test_a_cluster_worker_on_another_openblas_kernel_is_refused(workspace, cluster):
    """`dask worker` loads numpy before treegen can pin OpenBLAS's kernel (blas_kernel.py): a
    worker on another kernel writes trees a float32 step apart (a fan palm's trunk key), so it
    is refused before any job, with the variable that fixes it."""
    worker = subprocess.Popen(
        ["dask", "worker", cluster["address"], "--nthreads", "1", "--name", "sandy", "--host", "127.0.0.1"]
        + ["--no-dashboard"],
        env={**ENV, "OPENBLAS_CORETYPE": "Sandybridge"},
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        start_new_session=True,
    )
    try:
        from distributed import Client

        with Client(cluster["address"], timeout="30s") as client:
            client.wait_for_workers(len(client.scheduler_info()["workers"]) + 1, timeout=60)
        out = workspace / "refused_kernel"
        proc = treegen("batch", workspace / "catalogue.json", "-o", out, "--scheduler", cluster["address"])
        assert proc.returncode == 2, proc.stderr
        assert "kernel, worker" in proc.stderr and "Sandybridge" in proc.stderr, proc.stderr  # disagree
        assert "OPENBLAS_CORETYPE=Haswell dask worker" in proc.stderr
        assert len(proc.stderr.strip().splitlines()) == 1 and not out.exists()
    finally:
        os.killpg(worker.pid, signal.SIGKILL)
        worker.wait()


def test_worker_kernels_must_agree_and_match_this_process_on_x86():
    """check_kernels: a worker without OpenBLAS, workers that disagree, or (this process on
    x86-64 running OpenBLAS) a kernel other than this process's is refused with the variable
    to set; a client without OpenBLAS (another architecture's laptop) needs only agreement."""
    import platform

    from treegen_cli.cluster_check import check_kernels
    from treegen_cli.errors import TreegenError

    def refused(kernels, here="Haswell"):
        with pytest.raises(TreegenError) as e:
            check_kernels(kernels, here, "tcp://h:8786", "--scheduler tcp://h:8786")
        return str(e.value)

    assert "worker w1 runs no OpenBLAS" in refused({"w1": "none", "w2": "Haswell"})
    msg = refused({"w1": "Haswell", "w2": "SkylakeX"})
    assert "worker w1 runs OpenBLAS's Haswell kernel, worker w2 SkylakeX" in msg
    assert "OPENBLAS_CORETYPE=Haswell dask worker tcp://h:8786" in msg
    check_kernels({"w1": "SkylakeX", "w2": "SkylakeX"}, "none", "a", "b")  # agree: accepted
    if platform.machine().lower() in ("x86_64", "amd64"):
        assert "this process Haswell" in refused({"w1": "SkylakeX"})
    check_kernels({"w1": "Haswell", "w2": "Haswell"}, "Haswell", "a", "b")


@pytest.mark.parametrize(
    "address, said",
    [
        ("notaurl", "not a scheduler address; give tcp://HOST:PORT"),
        ("127.0.0.1", "not a scheduler address; give tcp://HOST:PORT"),
        ("tcp://127.0.0.1:99999", "not a scheduler address"),
        ("tcp://127.0.0.1:{free}", "cannot connect to a Dask scheduler"),
        ("tcp://127.0.0.1:{free}/", "not a scheduler address"),  # (Dask refuses the slash too)
    ],
)
def test_a_bad_scheduler_address_is_refused_in_one_line(workspace, tmp_path, address, said):
    """A mistyped address, or one nothing listens at, is refused at once in one line naming
    where it came from (Dask retried for 20 s and printed a traceback from Client.__del__)."""
    import socket

    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        free = sock.getsockname()[1]  # closed again: nothing listens there
    address = address.format(free=free)
    proc = treegen("batch", workspace / "catalogue.json", "-o", tmp_path / "o", "--scheduler", address)
    assert proc.returncode == 2 and proc.stderr.count("\n") == 1, proc.stderr
    assert proc.stderr.startswith(f"treegen: error: --scheduler {address}: {said}"), proc.stderr
    env = {**ENV, "DASK_SCHEDULER_ADDRESS": address}
    proc = treegen("batch", workspace / "catalogue.json", "-o", tmp_path / "o", env=env)
    assert f"DASK_SCHEDULER_ADDRESS={address}: {said}" in proc.stderr and proc.returncode == 2, proc.stderr
    assert not (tmp_path / "o").exists()


# ----------------------------------------------------------------------------- embedded cluster


def _listening_pid(address: str) -> int:
    """The process listening at a worker's tcp://HOST:PORT (the manifest's `worker`)."""
    import psutil

    port = int(address.rsplit(":", 1)[1])
    return next(c.pid for c in psutil.net_connections("tcp") if c.laddr and c.laddr.port == port and c.pid)


def test_embedded_local_cluster_is_tested_as_the_scheduler_path(workspace, serial):
    """Without --scheduler (an embedded cluster, 2 workers), as the --scheduler tests: a worker
    SIGKILLed mid-run (its nanny starts another, Dask runs its job again), a failing entry
    reported with its JSON path while the rest complete byte-identical and validator-clean; a
    rerun skips all 12 (the failing one fails again); a lost file is rebuilt alone; a changed
    option rebuilds only its jobs."""
    from treegen_cli.exchange.validate import validate_gltf

    out = workspace / "local"
    failing = json.loads(json.dumps(CATALOGUE))
    failing["entries"].append({"species": "species/weeping_willow.txt", "seeds": [1], "max_leaves": 1000})
    cat = workspace / "local_failing.json"
    cat.write_text(json.dumps(failing))
    args = [sys.executable, "-m", "treegen_cli", "batch", cat, "-o", out, "--workers", "2", "--json"]
    proc = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=ENV)
    lines, killed = [], None
    for line in proc.stdout:
        lines.append(line)
        if killed is None and '"event": "built"' in line:
            killed = _listening_pid(json.loads(line)["worker"])
            os.kill(killed, signal.SIGKILL)
    proc.wait(timeout=300)
    err = proc.stderr.read()
    assert proc.returncode == 1, err
    done = events("".join(lines))[-1]
    assert killed is not None and done["built"] == 12 and done["failed"] == 1, done
    assert [line for line in err.splitlines() if line.strip()][0].startswith(
        "treegen: failed: entries[3] seed 1 (weeping_willow_1.glb)"
    ), err
    assert_outputs(out, serial)
    for name in OUTPUTS:
        if name.endswith(".glb"):
            issues = validate_gltf((out / name).resolve())["issues"]
            assert issues["numErrors"] == 0 and issues["numWarnings"] == 0, name

    rerun = treegen("batch", cat, "-o", out, "--workers", "2", "--json")
    assert rerun.returncode == 1, rerun.stderr
    done = events(rerun.stdout)[-1]
    assert (done["skipped"], done["built"], done["failed"]) == (12, 0, 1), done

    (out / "rush_6.glb").unlink()  # a lost file is rebuilt, alone
    proc = treegen("batch", workspace / "catalogue.json", "-o", out, "--workers", "1", "--json")
    assert proc.returncode == 0, proc.stderr
    assert [e["path"] for e in events(proc.stdout) if e["event"] == "built"] == ["rush_6.glb"]
    assert_outputs(out, serial)

    changed = json.loads(json.dumps(CATALOGUE))
    changed["entries"][1]["grid"]["wind_speed"] = [2, 9]
    (workspace / "local_changed.json").write_text(json.dumps(changed))
    proc = treegen("batch", workspace / "local_changed.json", "-o", out, "--workers", "2", "-v")
    assert proc.returncode == 0, proc.stderr
    assert "built 2, skipped 10, failed 0 of 12" in proc.stdout and "2 local worker(s)" in proc.stdout
    assert sorted(
        line.split()[1] for line in proc.stderr.splitlines() if line.lstrip().startswith("built ")
    ) == [
        "pair_small_3_wind_speed-9.glb",
        "pair_small_4_wind_speed-9.glb",
    ]


def journaled(out: Path) -> set[str]:
    """The outputs the workers have journaled so far (whole lines only)."""
    try:
        lines = (out / ".manifest.jsonl").read_text().splitlines()
    except OSError:
        return set()
    paths = set()
    for line in lines:
        try:
            paths.add(json.loads(line)["path"])
        except (ValueError, KeyError):
            continue
    return paths


@pytest.mark.parametrize("stop", ["ctrl-c", "sigterm"])
def test_ctrl_c_keeps_what_landed_and_leaves_no_partial_files_or_empty_folders(workspace, stop):
    """Ctrl-C while an aspen's .usdc is being written, its .glb already in place: the task
    never returns, yet the .glb (journaled by its worker as it landed) is recorded as built
    and skipped by the rerun. The rush, last in line, writes into `later/`: that folder
    exists only if one of its jobs ran. No staging folder, journal or partial file is left.
    A SIGTERM to the batch process alone (a farm stopping the job) ends the same way, exit
    143 (it was killed at once: staging folders, no manifest, leaked semaphores)."""
    cat = json.loads(json.dumps(CATALOGUE))
    cat["entries"][2]["name"] = "later/{species}_{seed}.{ext}"
    catalogue = workspace / "interrupt.json"
    catalogue.write_text(json.dumps(cat))
    out = workspace / f"interrupted_{stop}"
    args = [sys.executable, "-m", "treegen_cli", "batch", catalogue, "-o", out, "--workers", "1", "--json"]
    proc = subprocess.Popen(
        args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=ENV, start_new_session=True
    )

    def half_written(landed: set[str]) -> list[str]:
        """Aspens whose .glb is in place and whose .usdc is not: their task is running."""
        pairs = [(f"quaking_aspen_{s}.glb", f"quaking_aspen_{s}.usdc") for s in (1, 2)]
        return [glb for glb, usdc in pairs if glb in landed and usdc not in landed]

    landed: set[str] = set()
    while not half_written(landed):
        if all(f"quaking_aspen_{s}.usdc" in landed for s in (1, 2)) or proc.poll() is not None:
            proc.kill()
            pytest.fail("no moment with an aspen's .glb in place and its .usdc not yet")
        time.sleep(0.005)
        landed = journaled(out)
    first = half_written(landed)[0]
    if stop == "ctrl-c":
        os.killpg(proc.pid, signal.SIGINT)  # the terminal sends Ctrl-C to the whole group
    else:
        os.kill(proc.pid, signal.SIGTERM)  # `kill PID`: the batch process alone
    stdout, err = proc.communicate(timeout=120)
    word = "interrupted" if stop == "ctrl-c" else "terminated"
    assert proc.returncode == (130 if stop == "ctrl-c" else 143), err
    assert "Traceback" not in err and f"treegen: {word}:" in err and "rerun" in err, err
    assert "leaked" not in err, err
    manifest = json.loads((out / "manifest.json").read_text())
    built = {r["path"]: r for r in manifest["assets"] if r["status"] == "built"}
    assert first in built and 1 <= len(built) < 12 and manifest["built"] == len(built)
    assert f"{word}: {len(built)} built" in err, err
    assert sorted(e["path"] for e in events(stdout) if e["event"] == "built") == sorted(built)
    pending = {r["path"] for r in manifest["assets"] if r["status"] == "pending"}
    assert pending == {r["path"] for r in manifest["assets"]} - set(built)
    # every asset on disk is a built one, whole: its files sum to the bytes recorded
    on_disk = {p.relative_to(out).as_posix() for p in out.rglob("*") if p.suffix in (".glb", ".usdc")}
    assert on_disk == set(built)
    for row in built.values():
        assert sum((out / f).stat().st_size for f in row["files"]) == row["bytes"], row["path"]
    assert [p.name for p in out.rglob(".*")] == []  # no staging folders, no journal
    assert [p for p in out.rglob("*") if p.is_dir() and not any(p.iterdir())] == []
    assert (out / "later").exists() == any(p.startswith("later/") for p in built)

    rerun = treegen("batch", catalogue, "-o", out, "--workers", "1", "--json")
    assert rerun.returncode == 0, rerun.stderr
    kinds = {e["path"]: e["event"] for e in events(rerun.stdout) if "path" in e}
    assert {p for p, k in kinds.items() if k == "skipped"} == set(built)
    assert {p for p, k in kinds.items() if k == "built"} == pending
    assert len(list((out / "later").glob("*.glb"))) == 4


@pytest.mark.parametrize("stop", ["ctrl-c", "sigterm"])
@pytest.mark.parametrize("start", ["starts", "fails"])
def test_a_stop_while_the_cluster_starts_stops_it_once_started(monkeypatch, stop, start):
    """A Ctrl-C or SIGTERM while the local Dask cluster starts (a few seconds): SIGINT was
    ignored there (a batch stopped at 2.5-3.5 s built everything and exited 0), and a
    SIGTERM left a half-started cluster to Dask's exit hook (a 28-line traceback), or stopped
    its workers too (a process group's) and "Nanny failed to start" ended the run with exit
    1. Now the signal is held until the cluster has started, which is then closed, and
    raised as itself whether or not the start got through."""
    from treegen_cli import executor
    from treegen_cli.errors import Terminated, raise_terminated

    closed = []

    class Cluster:
        def close(self):
            closed.append(True)

    def starting(n):
        os.kill(os.getpid(), signal.SIGINT if stop == "ctrl-c" else signal.SIGTERM)
        time.sleep(0.05)  # delivered here, in the middle of the start
        if start == "fails":
            raise RuntimeError("Nanny failed to start.")
        return Cluster()

    monkeypatch.setattr(executor, "start_fork_server", lambda: None)
    monkeypatch.setattr(executor, "_local_cluster", starting)
    before = {sig: signal.getsignal(sig) for sig in (signal.SIGINT, signal.SIGTERM)}
    signal.signal(signal.SIGTERM, raise_terminated)  # the CLI's (cli.main installs it)
    try:
        with pytest.raises(KeyboardInterrupt) as caught:
            with executor.dask_client(workers=1):
                pytest.fail("the client was handed out after a stop")
        assert isinstance(caught.value, Terminated) == (stop == "sigterm")
        assert closed == ([True] if start == "starts" else [])
        assert signal.getsignal(signal.SIGINT) is before[signal.SIGINT]  # handlers restored
    finally:
        signal.signal(signal.SIGTERM, before[signal.SIGTERM])


def test_held_signals_go_to_the_handlers_they_were_meant_for():
    """errors.signals_held: a Ctrl-C inside is raised once it is left (not inside), and one
    that was ignored before (a batch started in the background from a script: the shell
    ignores SIGINT for it) stays ignored, where it aborted the cluster's start."""
    from treegen_cli.errors import signals_held

    before = signal.getsignal(signal.SIGINT)
    try:
        for handler, raises in ((signal.default_int_handler, True), (signal.SIG_IGN, False)):
            signal.signal(signal.SIGINT, handler)
            reached = []
            try:
                with signals_held():
                    os.kill(os.getpid(), signal.SIGINT)
                    time.sleep(0.05)
                    reached.append(True)  # not interrupted inside
            except KeyboardInterrupt:
                reached.append("raised")
            assert reached == ([True, "raised"] if raises else [True]), handler
            assert signal.getsignal(signal.SIGINT) is handler
    finally:
        signal.signal(signal.SIGINT, before)


def test_a_signal_while_the_handlers_are_put_back_reaches_its_own(monkeypatch):
    """A Ctrl-C arriving just as signals_held puts SIGINT's handler back, with another thread
    alive (a Dask cluster's IO loop: it takes signals the main thread blocks), is raised, and
    SIGTERM's handler is put back too (it stayed the hold's, which swallowed every later
    SIGTERM: a CI cancel, `docker stop`)."""
    import threading

    from treegen_cli import errors

    real = signal.signal
    sent = []

    def put_back(sig, handler):
        out = real(sig, handler)
        if sig == signal.SIGINT and handler is signal.default_int_handler and not sent:
            sent.append(sig)
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(0.05)
        return out

    before = {sig: signal.getsignal(sig) for sig in (signal.SIGINT, signal.SIGTERM)}
    stop = threading.Event()
    other = threading.Thread(target=stop.wait)
    other.start()
    try:
        real(signal.SIGINT, signal.default_int_handler)
        real(signal.SIGTERM, errors.raise_terminated)
        monkeypatch.setattr(errors.signal, "signal", put_back)
        with pytest.raises(KeyboardInterrupt):
            with errors.signals_held():
                pass
        monkeypatch.undo()
        assert sent and signal.getsignal(signal.SIGTERM) is errors.raise_terminated
        assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
    finally:
        stop.set()
        other.join()
        for sig, handler in before.items():
            real(sig, handler)


def test_a_file_where_an_output_folder_goes_is_refused_before_anything_runs(workspace, tmp_path):
    cat = json.loads(json.dumps(CATALOGUE))
    cat["entries"][2]["name"] = "later/{species}_{seed}.{ext}"
    catalogue = workspace / "blocked.json"
    catalogue.write_text(json.dumps(cat))
    out = tmp_path / "out"
    out.mkdir()
    (out / "later").write_text("not a folder")
    proc = treegen("batch", catalogue, "-o", out)
    assert proc.returncode == 2, proc.stderr
    assert proc.stderr.strip() == (
        f"treegen: error: -o {out}: cannot create folder '{out / 'later'}' (a file of that name is there)"
    )
    assert sorted(p.name for p in out.iterdir()) == ["later"]


# ----------------------------------------------------------------------------- catalogue checks


@pytest.mark.parametrize(
    "change, needles",
    [
        ({"entries": [{"species": "species/nope.txt"}]}, ["entries[0].species", "nope.txt"]),
        (
            {"entries": [{"species": "species/rush.txt", "grid": {"wind_speed": [2, 200]}}]},
            ["entries[0].grid.wind_speed[1]", "200", "[0, 100]"],
        ),
        ({"entries": [{"species": "species/rush.txt", "seeds": "9-3"}]}, ["entries[0].seeds", "9-3"]),
        (
            {"entries": [{"species": "species/rush.txt", "wind_sped": 3}]},
            ["entries[0].wind_sped: unknown key (did you mean wind_speed?); allowed: "],
        ),
        (
            {"defaults": {"wnd_speed": 3}, "entries": [{"species": "species/rush.txt"}]},
            ["defaults.wnd_speed: unknown key (did you mean wind_speed?); allowed: "],
        ),
        (
            {"entries": [{"species": "species/rush.txt", "grid": {"gusst": [0.1]}}]},
            ["entries[0].grid.gusst: unknown key (did you mean gust?)"],
        ),
        (
            {"entries": [{"species": "species/rush.txt", "seeds": [1.5]}]},
            ["entries[0].seeds[0]: 1.5 is not a whole number; allowed [0, 9223372036854775807]"],
        ),
        (
            {"entries": [{"species": "species/rush.txt", "seeds": [1, 2, -3]}]},
            ["entries[0].seeds[2]: -3 is out of range; allowed [0, 9223372036854775807]"],
        ),
        (
            {"defaults": {"seeds": 2.5}, "entries": [{"species": "species/rush.txt"}]},
            ["defaults.seeds: 2.5 is not a whole number; allowed [0, 9223372036854775807]"],
        ),
        (
            {"entries": [{"species": "species/rush.txt", "seeds": [4, 9, 4]}]},
            ["entries[0].seeds[2]: seed 4 is listed twice"],
        ),
        (
            {"entries": [{"species": "species/rush.txt", "sides": [8, 4.5]}]},
            ["entries[0].sides[1]: 4.5 is not a whole number; allowed [3, 64]"],
        ),
        (
            {"entries": [{"species": "species/rush.txt", "grid": {"sides": [[8], [8, 4.5]]}}]},
            ["entries[0].grid.sides[1][1]: 4.5 is not a whole number; allowed [3, 64]"],
        ),
        (
            {"entries": [{"species": "species/rush.txt", "lod_distances": [0, "far"]}]},
            ['entries[0].lod_distances[1]: expected a number (finite), got "far"'],
        ),
        (
            {"defaults": {"lod_screen": [0.5, 200]}, "entries": [{"species": "species/rush.txt"}]},
            ["defaults.lod_screen[1]: 200 is out of range; allowed [0.0001, 4]"],
        ),
        (
            {"entries": [{"species": "species/rush.txt", "joint_levels": [0, True]}]},
            ["entries[0].joint_levels[1]: expected an integer, got true"],
        ),
        (
            {"entries": [{"species": "species/rush.txt", "grid": {"max_joints": [64, 2.5]}}]},
            ["entries[0].grid.max_joints[1]: 2.5 is not a whole number; allowed [1, 65535]"],
        ),
        (
            {"entries": [{"species": "species/rush.txt", "formats": ["glb", 3]}]},
            ["entries[0].formats[1]: expected a string, got 3"],
        ),
        (
            {"defaults": {"max_joints": 0}, "entries": [{"species": "species/rush.txt"}]},
            ["defaults.max_joints", "[1, 65535]"],
        ),
        (
            {"defaults": {"lod_distances": "30,10"}, "entries": [{"species": "species/rush.txt"}]},
            ["defaults.lod_distances", "ascending"],
        ),
        (
            {"entries": [{"species": "species/rush.txt", "formats": ["fbx"]}]},
            ["entries[0].formats[0]", "fbx", "glb"],
        ),
        ({"entries": [{"species": "species/rush.txt", "sides": [2]}]}, ["entries[0].sides", "[3, 64]"]),
        (
            {"entries": [{"species": "species/rush.txt", "name": "{species}.{ext}", "seeds": [1, 2]}]},
            ["entries[0]", "rush.glb", "also written by entries[0] (seed 1)"],
        ),
        (
            {"entries": [{"species": "species/rush.txt"}, {"species": "species/rush.txt"}]},
            ["entries[1]", "rush_0.glb", "entries[0]"],
        ),
        (
            {"entries": [{"species": "species/rush.txt", "name": "../{species}_{seed}.{ext}"}]},
            ["entries[0].name", "inside the output folder"],
        ),
        (
            {"entries": [{"species": "species/rush.txt", "wind_speed": 3, "grid": {"wind_speed": [1]}}]},
            ["entries[0].grid.wind_speed", "also set as entries[0].wind_speed"],
        ),
        # an artist's images are read before anything runs, relative to the catalogue
        (
            {"entries": [{"species": "species/rush.txt", "leaf_texture": "images/missing.png"}]},
            ["entries[0].leaf_texture", "images/missing.png: no such file"],
        ),
        (
            {"defaults": {"bark_texture": "images/not.png"}, "entries": [{"species": "species/rush.txt"}]},
            ["defaults.bark_texture", "images/not.png: not a PNG image"],
        ),
        (
            {
                "entries": [
                    {"species": "species/rush.txt", "no_textures": True, "leaf_texture": "images/leaf.png"}
                ]
            },
            ["entries[0].leaf_texture", "cannot be combined with entries[0].no_textures"],
        ),
        # make refuses --lod-files for a static format: a batch must not write LOD parts of it
        (
            {"entries": [{"species": "species/rush.txt", "formats": ["glb", "obj"], "lod_files": True}]},
            ["entries[0].lod_files: has no effect on entries[0].formats[1]", "static format"],
        ),
        (
            {
                "defaults": {"lod_files": True},
                "entries": [{"species": "species/rush.txt", "formats": ["ply"]}],
            },
            ["defaults.lod_files: has no effect on entries[0].formats[0]"],
        ),
        # as make refuses --duration for x.obj: an entry whose every format is static
        (
            {"entries": [{"species": "species/rush.txt", "formats": ["obj", "ply"], "duration": 2}]},
            ['entries[0].duration: has no effect, entries[0].formats ["obj", "ply"] holds no wind'],
        ),
        (  # 0 is given (make refuses --wind-speed 0 for x.obj), and the rig is void there too
            {"entries": [{"species": "species/rush.txt", "formats": ["obj"], "wind_speed": 0}]},
            ["entries[0].wind_speed: has no effect"],
        ),
        (
            {"entries": [{"species": "species/rush.txt", "formats": ["obj"], "joints": 6}]},
            ['entries[0].joints: has no effect, entries[0].formats ["obj"] holds no wind, LODs or skin'],
        ),
        (  # false is given too: an impostor either way is void without LODs
            {"entries": [{"species": "species/rush.txt", "formats": ["ply"], "impostor": False}]},
            ['entries[0].impostor: has no effect, entries[0].formats ["ply"] holds no wind, LODs or skin'],
        ),
        (
            {"entries": [{"species": "species/rush.txt", "no_lod": True, "impostor": True}]},
            ["entries[0].impostor: has no effect, entries[0].no_lod builds one LOD, never an impostor"],
        ),
    ],
)
def test_catalogue_errors_name_the_json_path_exit_2_and_write_nothing(workspace, change, needles):
    cat = workspace / "bad.json"
    cat.write_text(json.dumps(change))
    out = workspace / "never"
    proc = treegen("batch", cat, "-o", out)
    assert proc.returncode == 2, proc.stderr
    lines = [line for line in proc.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and "Traceback" not in proc.stderr, proc.stderr
    assert lines[0].startswith(f"treegen: error: {cat}: ")
    for n in needles:
        assert n in lines[0], lines[0]
    assert not out.exists()


def test_a_static_format_beside_others_is_what_make_writes(workspace):
    """An entry with glb and obj shares one build; the .obj and its manifest row are make's
    static file (LOD0's rest pose: one LOD, no joints, no keys), not the LODs the glb has."""
    cat = workspace / "static.json"
    entry = {"species": "species/rush.txt", "formats": ["glb", "obj"], "seeds": [2]}
    cat.write_text(json.dumps({"defaults": CLIP, "entries": [entry]}))
    dry = treegen("batch", cat, "-o", workspace / "st", "--dry-run", "--json")
    planned = {j["format"]: j for j in json.loads(dry.stdout)["jobs"]}  # the dry run says so too
    assert (len(planned["obj"]["triangles"]), planned["obj"]["joints"]) == (1, [0]), planned["obj"]
    proc = treegen("batch", cat, "-o", workspace / "st", "--workers", "1", "-q")
    assert proc.returncode == 0, proc.stderr
    rows = {a["format"]: a for a in json.loads((workspace / "st" / "manifest.json").read_text())["assets"]}
    assert len(rows["glb"]["triangles"]) > 1 and rows["glb"]["keys"][0] > 0
    obj = rows["obj"]
    assert (obj["triangles"], obj["joints"], obj["keys"]) == ([rows["glb"]["triangles"][0]], [0], [0])
    assert planned["obj"]["triangles"] == obj["triangles"]
    # every LOD as built (the plan lacked the atlas's leaf cells: LOD2 planned 9,067, built 5,417)
    assert planned["glb"]["triangles"] == rows["glb"]["triangles"]
    assert sorted(p.name for p in (workspace / "st").glob("rush_2*.obj")) == ["rush_2.obj"]
    (workspace / "m").mkdir()
    made = treegen("make", "species/rush.txt", "-o", workspace / "m" / "rush_2.obj", "--seed", "2", "-q")
    assert made.returncode == 0, made.stderr
    assert (workspace / "m" / "rush_2.obj").read_bytes() == (workspace / "st" / "rush_2.obj").read_bytes()


def test_a_rerun_removes_the_files_of_assets_the_catalogue_no_longer_lists(workspace):
    """Seeds or formats edited away: their files (as the earlier manifest recorded them) go,
    the dry run says so first; a file the manifest never recorded stays."""
    cat = workspace / "edited.json"
    out = workspace / "ed"

    def run(entry, *extra):
        cat.write_text(json.dumps({"defaults": CLIP, "entries": [entry]}))
        return treegen("batch", cat, "-o", out, "--workers", "1", *extra)

    assert run({"species": "species/rush.txt", "seeds": [1, 2], "formats": ["glb", "obj"]}).returncode == 0
    (out / "rush_2_notes.txt").write_text("the user's")
    dry = run({"species": "species/rush.txt", "seeds": [1]}, "--dry-run")
    assert "would remove 12 file(s) of assets the catalogue no longer lists" in dry.stdout, dry.stdout
    again = run({"species": "species/rush.txt", "seeds": [1]})
    assert again.returncode == 0 and "removed 12 file(s)" in again.stdout, again.stdout
    left = sorted(p.name for p in out.iterdir())
    assert left == [
        "manifest.csv",
        "manifest.json",
        "rush_1.glb",
        "rush_1.glb.impostor.json",
        "rush_2_notes.txt",
    ]
    assert json.loads((out / "manifest.json").read_text())["removed"] == 12


def test_seeds_grid_and_names_expand_as_documented(workspace):
    from treegen_cli.batch import parse_catalogue

    data = {
        "name": "{species}/{seed}.{ext}",
        "defaults": {"seeds": "1-2,7"},
        "entries": [
            {"species": "species/rush.txt", "grid": {"fps": [10, 12.5]}},
            {
                "species": "species/pair_small.txt",
                "seeds": [4],
                "name": "pair_w{wind_speed}_{seed}.{ext}",
                "formats": ["usda", "glb"],
                "grid": {"wind_speed": [3], "lod_distances": [[0, 15, 60]]},
            },
        ],
    }
    cat = parse_catalogue(data, workspace / "x.json")
    assert [j.output for j in cat.jobs] == [
        "rush/1_fps-10.glb",
        "rush/2_fps-10.glb",
        "rush/7_fps-10.glb",
        "rush/1_fps-12.5.glb",
        "rush/2_fps-12.5.glb",
        "rush/7_fps-12.5.glb",
        "pair_w3_4_lod_distances-0,15,60.usda",
        "pair_w3_4_lod_distances-0,15,60.glb",
    ]
    assert cat.jobs[-1].task == cat.jobs[-2].task and cat.jobs[-1].key != cat.jobs[-2].key
    assert len(cat.params) == 2  # each species parsed once


def test_artist_images_are_relative_to_the_catalogue_and_keyed_by_their_bytes(workspace, monkeypatch):
    """A leaf PNG named in a catalogue is found beside the catalogue (as species files are),
    whatever the working directory, and its bytes are part of the task's key: an edited image
    rebuilds, an unchanged one does not."""
    from treegen_cli.batch import parse_catalogue

    def task_at(path: Path, **entry) -> tuple:
        data = {"entries": [{"species": "species/rush.txt", "seeds": [1], **entry}]}
        cat = parse_catalogue(data, path)
        (job,) = cat.jobs
        return job.task, cat.resolved[job.task].options.materials.leaf_texture

    def task(**entry) -> tuple:
        return task_at(workspace / "x.json", **entry)

    monkeypatch.chdir(workspace)  # a relative catalogue path: the image is still absolute
    relative, rel_path = task_at(Path("x.json"), leaf_texture="images/leaf.png")
    assert rel_path == workspace / "images" / "leaf.png"
    plain, none = task()
    image = workspace / "images" / "edited.png"
    _png(image, (40, 160, 40, 255))
    first, path = task(leaf_texture="images/edited.png")
    again, _ = task(leaf_texture="images/edited.png")
    _png(image, (40, 120, 40, 255))
    edited, _ = task(leaf_texture="images/edited.png")
    assert none is None and path == image
    assert first == again and len({plain, first, edited}) == 3


def test_a_build_error_names_the_catalogue_key_not_the_make_flag(workspace):
    """Errors a tree's build raises (here the triangle budget, planned by --dry-run) come in
    `treegen make`'s words (`--triangles 5`); batch says which JSON path set the option."""
    cat = workspace / "tiny.json"
    cat.write_text(
        json.dumps({"entries": [{"species": "species/rush.txt", "seeds": [1], "grid": {"triangles": [5]}}]})
    )
    proc = treegen("batch", cat, "-o", workspace / "tiny", "--dry-run")
    assert proc.returncode == 1, proc.stderr
    assert "entries[0].grid.triangles[0] 5" in proc.stderr and "--triangles" not in proc.stderr, proc.stderr


def test_reword_names_only_what_the_catalogue_set(workspace):
    """Catalogue.reword: a flag of an option this job's catalogue set becomes its JSON path
    (`seeds` for --seed, `joints` for --max-joints when that alias was used, `impostor` false
    for --no-impostor); a flag the catalogue left to its default, or one inside a file path,
    stays as `make` wrote it."""
    from treegen_cli.batch import parse_catalogue

    data = {
        "defaults": {"seeds": [1], "impostor": True},
        "entries": [{"species": "species/rush.txt", "joints": 64, "grid": {"fps": [12]}}],
    }
    cat = parse_catalogue(data, workspace / "x.json")
    (job,) = cat.jobs
    said = "--seed 1, --max-joints 64, --fps 12, --wind-speed 9, --no-impostor; see /x/--fov/y"
    assert cat.reword(job, said) == (
        "defaults.seeds 1, entries[0].joints 64, entries[0].grid.fps[0] 12, --wind-speed 9, "
        "defaults.impostor false; see /x/--fov/y"
    )


def test_dry_run_prints_the_table_and_an_estimate_and_writes_nothing(workspace):
    out = workspace / "dry"
    proc = treegen("batch", workspace / "catalogue.json", "-o", out, "--dry-run", "--workers", "2", "-v")
    assert proc.returncode == 0, proc.stderr
    lines = proc.stdout.splitlines()
    assert len(lines) == 14 and "est MB" in lines[0] and "rush_8.glb" in lines[12]
    assert "12 jobs: 12 to build (10 trees)" in lines[-1] and "on 2 worker(s)" in lines[-1]
    assert not out.exists()  # (--json: test_dry_run_plans_what_the_run_builds_…)
    # -v: a line per tree as it is planned (a large catalogue's dry run was silent for minutes)
    planned = [line for line in proc.stderr.splitlines() if "planned" in line]
    assert len(planned) == 10 and planned[-1].startswith("  planned 10/10: entries[2] seed 8")


def test_estimated_textures_follow_the_atlas_the_build_makes():
    """The dry run's PNG bytes: the material maps at the texture size, the impostor atlas as
    resolved (an explicit --impostor-size, not twice the texture size), none in a PLY."""
    from treegen_cli.api import resolve
    from treegen_cli.batch.plan import _texture_bytes

    small = resolve({"texture_size": 256}).options
    big = resolve({"texture_size": 256, "impostor_size": 2048}).options
    assert big.impostor.grid * big.impostor.cell == 2048
    imp_small = _texture_bytes("glb", small, True) - _texture_bytes("glb", small, False)
    imp_big = _texture_bytes("glb", big, True) - _texture_bytes("glb", big, False)
    assert imp_big == pytest.approx(16 * imp_small)  # 2048² against 512²
    assert _texture_bytes("ply", big, True) == 0 and _texture_bytes("obj", big, True) < imp_big


def test_estimate_counts_the_planning_it_measured_and_the_budget_a_job_grows_to(tmp_path):
    """The dry run's seconds are the planning's own (measured, CPU) plus what the build adds
    (clip, impostor, bytes); without a plan (the run's ETA) a triangle budget caps the tree
    the model grows, as the build does (the mobile fir was estimated 22× too long)."""
    from treegen_cli.batch import estimate, load_catalogue, plan_jobs

    species = Path(__file__).resolve().parents[1] / "species"
    entries = [
        {"species": str(species / "balsam_fir.txt"), "seeds": [1]},
        {"species": str(species / "balsam_fir.txt"), "seeds": [1], "triangles": 20000, "name": "b.{ext}"},
    ]
    (tmp_path / "c.json").write_text(json.dumps({"defaults": {"formats": ["glb"]}, "entries": entries}))
    cat = load_catalogue(tmp_path / "c.json")
    plan = plan_jobs(cat, tmp_path / "out")
    full, budget = (estimate(cat, plan)[j.output] for j in plan.build)
    assert full[2] == budget[2] == "model" and budget[1] < 0.2 * full[1] and budget[0] < 0.2 * full[0]
    shape = [{"vertices": 1000, "triangles": 600, "joints": 10}]
    shapes = {j.task: shape for j in plan.build}
    measured = estimate(cat, plan, shapes, {j.task: 5.0 for j in plan.build})
    assert all(5.0 < measured[j.output][1] < 6.0 and measured[j.output][2] == "plan" for j in plan.build)


def test_dry_run_plans_what_the_run_builds_with_budgets_and_profiles(workspace):
    """--dry-run applies --profile, --triangles and --joints as the build does: per job the
    LOD count, triangles, joints and switch distances it prints are the manifest's after the
    real run, and a budget the species cannot meet is the same failure in both."""
    cat = workspace / "budgets.json"
    cat.write_text(
        json.dumps(
            {
                "defaults": {"duration": 1, "fps": 10},
                "entries": [
                    {"species": "species/rush.txt", "seeds": [1], "profile": "mobile"},
                    {
                        "species": "species/pair_small.txt",
                        "seeds": [2],
                        "triangles": 1500,
                        "joints": 6,
                        "formats": ["glb", "usda", "obj"],
                    },
                    {"species": "species/rush.txt", "seeds": [3], "triangles": 10, "name": "tiny.{ext}"},
                ],
            }
        )
    )
    out = workspace / "budgets"
    dry = treegen("batch", cat, "-o", out, "--dry-run", "--json")
    assert dry.returncode == 1 and not out.exists()
    assert dry.stderr.count("\n") == 1 and "would fail: entries[2] seed 3 (tiny.glb)" in dry.stderr
    doc = json.loads(dry.stdout)
    assert doc["build"] == 5 and doc["trees"] == 3 and doc["failing"] == 1
    assert doc["estimated_bytes"] > 0 and "plan" in doc["estimate"]
    planned = {j["path"]: j for j in doc["jobs"]}
    assert "use entries[2].triangles" in planned["tiny.glb"]["error"]
    rush, pair = planned["rush_1.glb"], planned["pair_small_2.glb"]
    assert rush["triangles"][0] <= 20_000 and max(rush["joints"]) <= 64  # the mobile row
    assert len(rush["triangles"]) == 4  # 0.3,0.1 switches + the impostor
    assert 1350 <= pair["triangles"][0] <= 1500 and pair["joints"][0] <= 6
    run = treegen("batch", cat, "-o", out, "--workers", "1")
    assert run.returncode == 1, run.stderr
    rows = {r["path"]: r for r in json.loads((out / "manifest.json").read_text())["assets"]}
    assert rows["tiny.glb"]["status"] == "failed"
    for path, job in planned.items():
        if path == "tiny.glb":
            continue
        row = rows[path]
        assert row["status"] == "built"
        for key in ("triangles", "joints", "lod_distances_m"):
            assert job[key] == row[key], (path, key)
        # sizes per format: an OBJ is text, USD text or crate, glTF maybe compressed; each with
        # its textures (an OBJ was estimated 2-11x low, without them); the impostor atlas's PNG
        # bytes follow its crown's fill, which only rendering tells
        assert 0.7 <= row["bytes"] / job["estimated_bytes"] <= 1.4, (
            path,
            row["bytes"],
            job["estimated_bytes"],
        )


def test_a_catalogue_over_the_job_limit_is_refused_unless_raised(tmp_path):
    """ "1-100000" typed for "1-10": refused before anything runs, naming --max-jobs (default
    MAX_JOBS); raised, the same catalogue expands."""
    from treegen_cli.batch import MAX_JOBS, parse_catalogue
    from treegen_cli.errors import TreegenError

    rush = str(ROOT / "species" / "rush.txt")
    data = {"entries": [{"species": rush, "seeds": f"1-{MAX_JOBS + 1}"}]}
    with pytest.raises(
        TreegenError, match=rf"over the limit of {MAX_JOBS:,} jobs; raise it with --max-jobs N"
    ):
        parse_catalogue(data, tmp_path / "c.json")
    assert len(parse_catalogue(data, tmp_path / "c.json", MAX_JOBS + 1).jobs) == MAX_JOBS + 1
    data = {"entries": [{"species": rush, "seeds": "1-6000", "formats": ["glb", "usdc"]}]}
    with pytest.raises(
        TreegenError, match=rf"more than {MAX_JOBS:,} jobs; raise the limit with --max-jobs N"
    ):
        parse_catalogue(data, tmp_path / "c.json")
    (tmp_path / "c.json").write_text(json.dumps({"entries": [{"species": rush, "seeds": "1-5"}]}))
    proc = treegen("batch", tmp_path / "c.json", "-o", tmp_path / "o", "--max-jobs", "3", "--dry-run")
    assert proc.returncode == 2 and "gives 5 seeds, over the limit of 3 jobs" in proc.stderr, proc.stderr
    assert not (tmp_path / "o").exists()


def test_seeds_name_the_bad_item_and_the_whole_seed_range():
    """parse_seeds (the API's path, after the schema) names a list item by its index."""
    from treegen_cli.batch import parse_seeds
    from treegen_cli.errors import TreegenError
    from treegen_cli.options import MAX_SEED

    assert parse_seeds([5, MAX_SEED], "s") == [5, MAX_SEED] and parse_seeds("1-3,7", "s") == [1, 2, 3, 7]
    for value, message in (
        ([1.5], f"s[0]: 1.5 is not a whole number; allowed [0, {MAX_SEED}]"),
        ([1, "x"], f's[1]: expected a seed (a whole number), got "x"; allowed [0, {MAX_SEED}]'),
        ([1, MAX_SEED + 1], f"s[1]: seed {MAX_SEED + 1} is out of range; allowed [0, {MAX_SEED}]"),
        (2.5, f"s: 2.5 is not a whole number; allowed [0, {MAX_SEED}]"),
        ([3, 1, 3], "s[2]: seed 3 is listed twice"),
    ):
        with pytest.raises(TreegenError) as e:
            parse_seeds(value, "s")
        assert str(e.value) == message


def test_schema_and_defaults_agree_with_make():
    from treegen_cli import api
    from treegen_cli.commands.make import make

    schema = json.loads(treegen("batch", "--schema").stdout)
    entry = schema["$defs"]["entry"]["properties"]
    assert set(api.DEFAULTS) - {"seed"} <= set(entry)
    assert set(schema["properties"]["defaults"]["properties"]) == set(api.DEFAULTS) - {"seed"} | {
        "seeds",
        "formats",
    }
    from treegen_cli.options import MAX_SEED

    seeds = schema["$defs"]["seeds"]["anyOf"]
    assert [b.get("maximum", b.get("items", {}).get("maximum")) for b in seeds] == [MAX_SEED, None, MAX_SEED]
    click_defaults = {p.name: p.default for p in make.params if p.name in api.DEFAULTS}
    assert click_defaults == api.DEFAULTS
    for k, v in api.DEFAULTS.items():
        if "default" in schema["$defs"].get(k, {}):
            assert schema["$defs"][k]["default"] == v, k


def test_api_make_validates_like_the_cli(tmp_path):
    from treegen_cli import api
    from treegen_cli.errors import TreegenError

    with pytest.raises(TreegenError, match=r"^--max-joints 0: the joint budget must be at least 1$"):
        api.make(ROOT / "species" / "rush.txt", tmp_path / "r.glb", max_joints=0)
    with pytest.raises(TreegenError, match="unknown make option 'wind'"):
        api.make(ROOT / "species" / "rush.txt", tmp_path / "r.glb", wind=3)
    with pytest.raises(TreegenError, match=r"--lod-distances 'a,b': expected comma-separated metres"):
        api.make(ROOT / "species" / "rush.txt", tmp_path / "r.glb", lod_distances="a,b")
    assert not list(tmp_path.iterdir())
    s = api.make(
        ROOT / "tests" / "fixtures" / "pair_small.txt",
        tmp_path / "p.glb",
        seed=2,
        lod_distances=[0, 30],
        **{k: v for k, v in CLIP.items() if k != "lod_distances"},
    )
    assert s["file"] == str(tmp_path / "p.glb") and s["seed"] == 2
    assert len(s["lods"]) == 3 and s["lods"][-1]["triangles"] == 8  # + the impostor


def test_staging_sweep_leaves_other_hosts_folders_alone(tmp_path):
    """On a folder shared by several machines a process id means nothing on another host: a
    dead writer's staging folder is swept only by its own host."""
    from treegen_cli.exchange import staging

    dead = subprocess.run(
        [sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True
    ).stdout.strip()
    mine = tmp_path / f".a.glb.{dead}@{staging._HOST}.abcd1234.tmp"
    other = tmp_path / f".b.glb.{dead}@some-other-host.abcd1234.tmp"
    for d in (mine, other):
        d.mkdir()
    assert staging.sweep(tmp_path) == [mine]
    assert other.exists()


def test_errors_cross_process_boundaries_whole():
    """A build's error reaches the client through pickling (Dask's comms, the forest's process
    pool): TreegenError keeps its line, OptionError its field, value, rule and message."""
    import pickle

    from treegen_cli.errors import OptionError, TreegenError

    e = pickle.loads(pickle.dumps(TreegenError("Levels = 9: allowed 0..9", line=7)))
    assert (str(e), e.line) == ("Levels = 9: allowed 0..9", 7)
    o = pickle.loads(pickle.dumps(OptionError("speed", 70.0, "allowed range [0, 60] m/s", "--wind-speed")))
    assert isinstance(o, OptionError) and (o.field, o.value, o.label) == ("speed", 70.0, "--wind-speed")
    assert str(o) == "--wind-speed 70: allowed range [0, 60] m/s"

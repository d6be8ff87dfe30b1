"""Bulk meshing runs (jaxmatch/batch.py): one record and one mesh per region, appended as they
come; --resume after a SIGKILL; the per-region budget; Dask; the progress line; every summary
field documented."""

from __future__ import annotations

import json
import os
import resource
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import meshio
import pytest

import jaxmatch

from jaxmatch import batch, cli as cli_mod
from jaxmatch.errors import EXIT_BAD_INPUT

ROOT = Path(__file__).resolve().parent.parent
EX = ROOT / "examples"
MSH = ("--msh-version", "2.2")
"""Every run here writes MSH 2.2 (the bench compares with references that wrote it)."""
SLOW = EX / "dense" / "coastline.json"
"""A region that takes ~3 s at perimeter / 32 on a quiet core."""


def _command(*args, **kw) -> subprocess.Popen:
    env = {**os.environ, "JAX_PLATFORMS": "cpu", "JAXMATCH_PROGRESS": "0"}
    return subprocess.Popen([sys.executable, "-m", "jaxmatch", "mesh", *map(str, args)], cwd=ROOT, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, **kw)


def _run(*args) -> tuple[int, str, float]:
    t = time.perf_counter()
    p = _command(*args)
    _, err = p.communicate(timeout=600)
    return p.returncode, err, time.perf_counter() - t


def _children_cpu() -> float:
    """CPU seconds (user + system) of this process's waited-for children and their waited-for
    descendants so far (a finished ``jaxmatch mesh`` run joins its workers)."""
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def _tree_cpu(pid: int) -> float:
    """CPU seconds (user + system) spent so far by the running process ``pid`` and its living
    descendants, from /proc (Linux), read just before a SIGKILL (whose workers are then reaped by
    init, out of :func:`_children_cpu`'s reach)."""
    tick = os.sysconf("SC_CLK_TCK")
    total, todo = 0.0, [pid]
    while todo:
        p = todo.pop()
        try:
            fields = Path(f"/proc/{p}/stat").read_text().rsplit(")", 1)[1].split()
            total += (int(fields[11]) + int(fields[12])) / tick  # utime, stime (fields 14, 15)
            for task in Path(f"/proc/{p}/task").iterdir():
                todo += [int(c) for c in (task / "children").read_text().split()]
        except (FileNotFoundError, ProcessLookupError):
            continue
    return total


def _records(out: Path) -> list[dict]:
    return [json.loads(line) for line in (out / "summary.jsonl").read_text().splitlines()]


def _meshes(out: Path) -> list[Path]:
    return sorted(p for p in out.glob("*.msh") if not p.name.startswith("."))


# ---------------------------------------------------------------------------------------------
# the budget of one region


def _spin(seconds: float) -> None:
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        pass


@pytest.mark.parametrize("thread", [False, True])
def test_deadline_stops_python_code_in_the_main_thread_and_in_others(thread):
    out = {}

    def body():
        t = time.monotonic()
        try:
            with batch.deadline(0.2):
                _spin(5.0)
            out["result"] = "finished"
        except batch.RegionTimedOut:
            out["result"] = "timed out"
        out["seconds"] = time.monotonic() - t
        with batch.deadline(5.0):  # a block that ends in time is left alone, and nothing fires later
            _spin(0.05)
        _spin(0.1)

    if thread:
        th = threading.Thread(target=body)
        th.start()
        th.join()
    else:
        body()
    assert out["result"] == "timed out" and 0.15 <= out["seconds"] < 2.0


def test_deadline_is_not_an_ordinary_exception():
    """Meshing code that turns an Exception into a failed candidate must not swallow the budget."""
    assert not issubclass(batch.RegionTimedOut, Exception)
    with pytest.raises(batch.RegionTimedOut):
        with batch.deadline(0.1):
            try:
                _spin(5.0)
            except Exception:  # noqa: BLE001 - what the test is about
                pass


def test_a_worker_stuck_in_compiled_code_is_killed_and_replaced(tmp_path, monkeypatch):
    """A region that ignores the budget (here: SIGALRM blocked, as in a long C call) is killed
    ``grace`` seconds past it; its record says timed out and the other regions still finish."""
    jobs = [batch.Job(i, f"r{i}", str(tmp_path / f"r{i}.msh"), "h") for i in range(6)]

    def fake(job, region, options, opts, region_budget, write):
        if job.index == 2:
            signal.pthread_sigmask(signal.SIG_BLOCK, [signal.SIGALRM])
            time.sleep(60)
        return batch._stamp({"shape": job.shape, "status": "meshed", "pid": os.getpid()}, job, opts)

    monkeypatch.setattr(batch, "mesh_job", fake)
    t = time.monotonic()
    got = dict(batch._local_results(jobs, [None] * 6, {}, "o", 0.5, 2, None, grace=0.5))
    assert time.monotonic() - t < 20
    assert sorted(got) == list(range(6))
    assert got[2]["status"] == "timed out" and got[2]["region_budget"] == 0.5 and got[2]["options_hash"] == "o"
    assert all(got[i]["status"] == "meshed" for i in (0, 1, 3, 4, 5))


@pytest.mark.slow
def test_a_region_past_the_region_budget_gets_its_record_and_the_others_finish(tmp_path):
    slow = SLOW
    quick = [EX / "square.json", EX / "lshape.json", EX / "tshape.json", EX / "plus.json"]
    out = tmp_path / "out"
    code, err, _ = _run(quick[0], quick[1], slow, quick[2], quick[3], "--divisions", "32", "--out-dir", out,
                        "--jobs", "2", "--region-budget", "1", *MSH)
    assert code == 0, err
    recs = _records(out)
    assert [r["shape"] for r in recs] == [str(p) for p in (quick[0], quick[1], slow, quick[2], quick[3])]
    assert recs[2]["status"] == "timed out" and recs[2]["region_budget"] == 1.0 and 1.0 <= recs[2]["seconds"] < 10
    assert [r["status"] for r in recs[:2] + recs[3:]] == ["meshed"] * 4
    assert not (out / "coastline.msh").exists() and len(_meshes(out)) == 4
    assert "1 timed out" in err


# ---------------------------------------------------------------------------------------------
# resume


@pytest.mark.slow
def test_a_run_killed_with_sigkill_resumes_with_one_record_and_one_mesh_per_region(tmp_path, bulk_parts):
    """One whole run (reference), then the same run killed part-way with SIGKILL and resumed:
    one record and one mesh file per region, the same meshes as the whole run, the regions
    done before the kill not meshed again, and the two runs together within 1.3x the whole one
    (CPU seconds of each command and its workers)."""
    paths = bulk_parts(tmp_path / "parts", 80)
    opts = ["--divisions", "24", "--jobs", "2"]
    c = _children_cpu()
    code, err, whole = _run(*paths, "--out-dir", tmp_path / "whole", *opts, *MSH)
    whole_cpu = _children_cpu() - c
    assert code == 0, err
    out = tmp_path / "out"
    t = time.perf_counter()
    proc = _command(*paths, "--out-dir", out, *opts, *MSH)
    summary = out / "summary.jsonl"
    while proc.poll() is None and (not summary.exists() or len(summary.read_bytes().splitlines()) < 30):
        time.sleep(0.02)
    first_cpu = _tree_cpu(proc.pid)
    proc.send_signal(signal.SIGKILL)
    proc.communicate()
    first = time.perf_counter() - t
    assert proc.returncode == -signal.SIGKILL
    before = {r["shape"]: r for r in _records(out)}  # every line a whole record
    assert 30 <= len(before) < len(paths)
    c = _children_cpu()
    code, err, second = _run(*paths, "--out-dir", out, *opts, "--resume", *MSH)
    second_cpu = _children_cpu() - c
    assert code == 0, err
    assert f"{len(before)} of {len(paths)} regions already meshed" in err
    recs = _records(out)
    assert [r["shape"] for r in recs] == [str(p) for p in paths]
    assert [m.stem for m in _meshes(out)] == [p.stem for p in paths]
    assert all(r["status"] == "meshed" for r in recs)
    for r in recs:
        if r["shape"] in before:
            assert r == before[r["shape"]]  # kept, not meshed again
    assert [r["quads"] for r in recs] == [r["quads"] for r in _records(tmp_path / "whole")]
    for m in _meshes(out):
        assert m.read_bytes() == (tmp_path / "whole" / m.name).read_bytes()
    print(f"whole run {whole:.2f} s ({whole_cpu:.2f} CPU s); killed after {first:.2f} s ({first_cpu:.2f} CPU s) with "
          f"{len(before)} of {len(paths)} records, resumed in {second:.2f} s ({second_cpu:.2f} CPU s): "
          f"{(first + second) / whole:.2f}x wall, {(first_cpu + second_cpu) / whole_cpu:.2f}x CPU")
    # CPU seconds of the process trees (the command and its workers): what the runs cost, unmoved by what else the
    # machine runs meanwhile (wall time on two shared cores is not); the killed run's is read just before the kill
    assert first_cpu + second_cpu <= 1.3 * whole_cpu, (first_cpu, second_cpu, whole_cpu)


def test_resume_keeps_only_records_of_the_same_input_and_options(cli, tmp_path):
    folder = tmp_path / "in"
    folder.mkdir()
    for name in ("a", "b", "c"):
        (folder / f"{name}.json").write_text((EX / "square.json").read_text())
    paths = sorted(folder.glob("*.json"))
    out = tmp_path / "out"
    code, _, err = cli("mesh", *paths, "--divisions", "8", "--out-dir", out, *MSH)
    assert code == 0, err
    first = _records(out)
    assert len({r["input_hash"] for r in first}) == 1 and len({r["options_hash"] for r in first}) == 1
    (folder / "b.json").write_text((EX / "lshape.json").read_text())  # another region under the same name
    (out / "c.msh").unlink()  # a mesh file gone
    code, _, err = cli("mesh", *paths, "--divisions", "8", "--out-dir", out, "--resume", *MSH)
    assert code == 0, err
    assert "1 of 3 regions already meshed" in err
    recs = _records(out)
    assert recs[0] == first[0] and recs[1]["quads"] != first[1]["quads"] and (out / "c.msh").exists()
    code, _, err = cli("mesh", *paths, "--divisions", "16", "--out-dir", out, "--resume", *MSH)  # other options: all again
    assert code == 0, err
    assert "0 of 3 regions already meshed" in err
    assert len(_records(out)) == 3 and {r["options_hash"] for r in _records(out)} != {first[0]["options_hash"]}


def test_a_torn_last_line_is_ignored_with_a_note(cli, tmp_path):
    out = tmp_path / "out"
    paths = [EX / "square.json", EX / "lshape.json"]
    assert cli("mesh", *paths, "--divisions", "8", "--out-dir", out, *MSH)[0] == 0
    text = (out / "summary.jsonl").read_text()
    (out / "summary.jsonl").write_text(text + text.splitlines()[0][:40])
    code, _, err = cli("mesh", *paths, "--divisions", "8", "--out-dir", out, "--resume", *MSH)
    assert code == 0, err
    assert "1 line(s) that are not a record ignored" in err and "2 of 2 regions already meshed" in err
    assert (out / "summary.jsonl").read_text() == text


@pytest.mark.parametrize("args, where", [(["--resume"], "--resume"), (["--region-budget", "0"], "--region-budget")])
def test_bulk_options_are_checked(cli, tmp_path, args, where):
    if where == "--resume":  # one region without --out-dir: not a bulk run
        code, _, err = cli("mesh", EX / "square.json", *args)
    else:
        code, _, err = cli("mesh", EX / "square.json", EX / "lshape.json", "--out-dir", tmp_path / "o", *args, *MSH)
    assert code == EXIT_BAD_INPUT and where in err and len(err.strip().splitlines()) == 1


# ---------------------------------------------------------------------------------------------
# progress and the summary's fields


def test_progress_shows_the_rate_and_the_time_left(cli, tmp_path, monkeypatch):
    assert batch._rate_text(10, 30, time.monotonic() - 5.0) == "regions (2.0/s, ~10 s left)"
    assert batch._rate_text(0, 30, time.monotonic()) == "regions"
    monkeypatch.setattr(cli_mod, "HEARTBEAT_S", 0.0)
    monkeypatch.delenv("JAXMATCH_PROGRESS", raising=False)
    code, _, err = cli("mesh", EX / "square.json", EX / "lshape.json", "--divisions", "8", "--out-dir", tmp_path / "o", *MSH)
    assert code == 0, err
    assert "regions (" in err and "/s, ~" in err and "s left): 2/2" in err


def test_every_field_of_a_summary_record_is_documented(cli, tmp_path):
    bad = tmp_path / "bad.json"
    bad.write_text('{"boundary": [[0, 0], [1, 0]]}')
    out = tmp_path / "o"
    code, _, err = cli("mesh", EX / "square.json", bad, "--divisions", "8", "--out-dir", out, "--skip-bad", *MSH)
    assert code == 0, err
    recs = _records(out)
    assert [r["status"] for r in recs] == ["meshed", "failed"]
    timed = batch.mesh_job(batch.Job(0, "x", str(tmp_path / "x.msh"), "h"), jaxmatch.load_shape(EX / "square.json"),
                           {"divisions": 64}, "o", 1e-6, lambda target, m: target)
    assert timed["status"] == "timed out"
    keys = set().union(*recs, timed)
    assert keys <= set(batch.RECORD_FIELDS), keys - set(batch.RECORD_FIELDS)
    assert "seconds" in recs[0] and recs[0]["seconds"] > 0
    text = (ROOT / "docs" / "reference.md").read_text()
    table = text[text.index("### The summary of a bulk run"):]
    for name in batch.RECORD_FIELDS:
        assert f"| `{name}` |" in table, name


def test_the_mesh_files_read_back(cli, tmp_path):
    out = tmp_path / "o"
    code, _, err = cli("mesh", EX / "square.json", EX / "lshape.json", "--divisions", "8", "--out-dir", out, *MSH)
    assert code == 0, err
    for r in _records(out):
        assert len(meshio.read(r["out"]).cells_dict["quad"]) == r["quads"]


# ---------------------------------------------------------------------------------------------
# Dask


def test_dask_missing_is_one_line(cli, tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "distributed", None)  # import fails as if not installed
    code, _, err = cli("mesh", EX / "square.json", EX / "lshape.json", "--out-dir", tmp_path / "o",
                       "--dask", "tcp://127.0.0.1:1")
    assert code == EXIT_BAD_INPUT and "--dask" in err and "jaxmatch[dask]" in err
    assert len(err.strip().splitlines()) == 1


@pytest.mark.slow
def test_dask_local_cluster_gives_the_local_meshes(tmp_path, monkeypatch, bulk_parts):
    """60 parts on a LocalCluster of two worker processes: the local run's meshes, byte for byte;
    --skip-bad, --resume and --region-budget as in a local run."""
    distributed = pytest.importorskip("distributed")
    monkeypatch.setenv("PYTHONPATH", str(ROOT))  # the workers import this checkout's jaxmatch, as the client does
    paths = bulk_parts(tmp_path / "parts", 60)
    bad = tmp_path / "parts" / "bad.json"
    bad.write_text('{"boundary": [[0, 0], [1, 0]]}')
    code, err, _ = _run(*paths, "--divisions", "16", "--out-dir", tmp_path / "local", "--jobs", "2", *MSH)
    assert code == 0, err
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster:
        dask = ("--dask", cluster.scheduler_address)
        code, err, _ = _run(*paths, bad, "--divisions", "16", "--out-dir", tmp_path / "dask", *dask, "--skip-bad", *MSH)
        assert code == 0, err
        workers = len(cluster.workers)
        remote = _records(tmp_path / "dask")
        code, err, _ = _run(*paths, bad, "--divisions", "16", "--out-dir", tmp_path / "dask", *dask, "--skip-bad",
                            "--resume", *MSH)
        assert code == 0, err
        assert "60 of 61 regions already meshed" in err and _records(tmp_path / "dask")[:60] == remote[:60]
        code, err, _ = _run(SLOW, EX / "square.json", "--divisions", "32", "--out-dir", tmp_path / "budget", *dask,
                            "--region-budget", "1", *MSH)
        assert code == 0, err
        assert [r["status"] for r in _records(tmp_path / "budget")] == ["timed out", "meshed"]
    assert workers == 2
    local = _records(tmp_path / "local")
    assert len(remote) == 61 and remote[60]["status"] == "failed" and str(bad) in remote[60]["error"]
    remote = remote[:60]
    assert all(r["status"] == "meshed" for r in remote)
    assert [r["quads"] for r in remote] == [r["quads"] for r in local]
    assert [r["out"] for r in remote] == [str(tmp_path / "dask" / Path(r["out"]).name) for r in local]
    for r in remote:
        assert Path(r["out"]).read_bytes() == (tmp_path / "local" / Path(r["out"]).name).read_bytes()


@pytest.mark.slow  # the client waits 10 s for the scheduler
def test_dask_unreachable_is_one_line(cli, tmp_path):
    pytest.importorskip("distributed")
    code, _, err = cli("mesh", EX / "square.json", EX / "lshape.json", "--out-dir", tmp_path / "o",
                       "--dask", "tcp://127.0.0.1:9", *MSH)
    assert code == EXIT_BAD_INPUT and "--dask" in err and "cannot reach a Dask scheduler" in err
    assert len(err.strip().splitlines()) == 1


def test_the_options_hash_covers_the_search_and_automatic_sizing():
    """A run with ``--search fast`` or ``--auto-size`` is not resumed from one without (their meshes
    differ); the best search named or not, and no automatic sizing, hash as before."""
    writing = cli_mod.MeshOutput(None, "4.1", True, None, 1, False, None, 1, 1.0)
    base = {"size": None, "divisions": 32, "strategies": None, "budget_s": 60.0, "catalogue": None, "lattice": "fine"}
    h = batch.options_hash(base, writing, 30.0)
    assert batch.options_hash({**base, "search": "best"}, writing, 30.0) == h
    assert batch.options_hash({**base, "auto_size": False}, writing, 30.0) == h
    fast, auto = (batch.options_hash({**base, **extra}, writing, 30.0) for extra in ({"search": "fast"}, {"auto_size": True}))
    assert len({h, fast, auto}) == 3

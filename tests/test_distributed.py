"""score-many shared among processes with jax.distributed (jaxmatch.scoring.distributed).

The two-process run starts two real CPU processes on the loopback interface (a free port,
bounded time) and checks that the merged output is byte for byte the single-process output.
"""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from jaxmatch.errors import InputError
from jaxmatch.scoring.distributed import Cluster, gather_records, make_cluster, parse_address, share

ROOT = Path(__file__).resolve().parents[1]
SHAPES = [ROOT / "examples" / n for n in ("lshape.json", "square.json", "triangle.json", "hexagon.json", "tshape.json")]


@pytest.mark.parametrize("text, expected", [("127.0.0.1:1234", "127.0.0.1:1234"), ("host0:65535", "host0:65535"),
                                            ("[::1]:80", "[::1]:80")])
def test_parse_address_accepts(text, expected):
    assert parse_address(text) == expected


@pytest.mark.parametrize("text", ["127.0.0.1", ":1234", "host:0", "host:65536", "host:port", ""])
def test_parse_address_rejects(text):
    with pytest.raises(InputError, match="HOST:PORT"):
        parse_address(text)


@pytest.mark.parametrize("p, i, problem", [(0, 0, "at least 1"), (2, 2, "0..1"), (3, -1, "0..2")])
def test_make_cluster_rejects(p, i, problem):
    with pytest.raises(InputError, match=problem):
        make_cluster("localhost:1234", p, i)


@pytest.mark.parametrize("count", [0, 1, 5, 8])
@pytest.mark.parametrize("procs", [1, 2, 3])
def test_share_partitions_the_inputs(count, procs):
    parts = [share(count, Cluster("h:1", procs, i)) for i in range(procs)]
    together = np.sort(np.concatenate(parts))
    assert together.tolist() == list(range(count))
    assert max(len(p) for p in parts) - min(len(p) for p in parts) <= 1


def test_gather_records_one_process_orders_and_checks():
    one = Cluster("", 1, 0)
    recs = [{"shape": "b"}, {"shape": "a"}]
    assert gather_records(recs, [1, 0], 2, one) == [{"shape": "a"}, {"shape": "b"}]
    with pytest.raises(ValueError, match="missing"):
        gather_records(recs[:1], [0], 2, one)
    with pytest.raises(ValueError, match="twice"):
        gather_records(recs, [0, 0], 2, one)


def _free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _score_many(out: Path, cache: Path, *extra: str) -> subprocess.Popen:
    env = dict(os.environ, JAX_PLATFORMS="cpu", JAXMATCH_CACHE=str(cache))
    env.pop("XLA_FLAGS", None)
    cmd = [sys.executable, "-m", "jaxmatch.cli", "score-many", *map(str, SHAPES), "--out", str(out),
           "--internal", "0..3", "--top", "3", "--tie-break", "id", *extra]
    return subprocess.Popen(cmd, cwd=ROOT, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def _finish(p: subprocess.Popen, timeout: float = 240) -> tuple[int, str]:
    try:
        _, err = p.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        p.kill()
        _, err = p.communicate()
        pytest.fail(f"process did not finish in {timeout} s: {err[-2000:]}")
    return p.returncode, err


@pytest.mark.slow  # three CLI processes with cold compiles: 25-45 s on 2 shared cores
def test_two_processes_merge_to_the_single_process_result(tmp_path):
    port = _free_port()
    cache = tmp_path / "cache"
    outs = [tmp_path / "p0.jsonl", tmp_path / "p1.jsonl"]
    procs = [_score_many(outs[i], cache, "--coordinator", f"127.0.0.1:{port}", "--num-processes", "2",
                         "--process-id", str(i)) for i in range(2)]
    results = [_finish(p) for p in procs]
    for code, err in results:
        assert code == 0, err[-2000:]
    assert outs[0].exists() and not outs[1].exists()  # process 0 writes, process 1 only scores its share
    single = tmp_path / "single.jsonl"
    code, err = _finish(_score_many(single, cache))
    assert code == 0, err[-2000:]
    assert outs[0].read_bytes() == single.read_bytes()
    lines = [json.loads(x) for x in single.read_text().splitlines()]
    assert [Path(r["shape"]).name for r in lines] == [s.name for s in SHAPES]
    assert all(r["results"] for r in lines)


@pytest.mark.parametrize("extra, problem", [
    (["--num-processes", "2"], "needs --coordinator"),
    (["--coordinator", "localhost"], "HOST:PORT"),
    (["--coordinator", "localhost:1234", "--num-processes", "2", "--process-id", "2"], "0..1"),
    (["--coordinator", "localhost:1234", "--devices", "2"], "not both"),
])
def test_cluster_options_are_checked_before_any_work(tmp_path, extra, problem):
    out = tmp_path / "o.jsonl"
    code, err = _finish(_score_many(out, tmp_path / "cache", *extra), timeout=120)
    assert code == 2
    assert problem in err and len(err.strip().splitlines()) == 1
    assert not out.exists()

"""jaxmatch.parallel.ordered_map: a process pool that behaves like a plain loop."""

from __future__ import annotations

import subprocess
import sys
import textwrap

import pytest

from jaxmatch.parallel import available_cpus, ordered_map


def in_fresh_python(code: str) -> None:
    """Run ``code`` in a new interpreter (where JAX is not loaded, so the pool is used; other
    test modules of this process may have imported it); it fails by raising."""
    r = subprocess.run([sys.executable, "-c", textwrap.dedent(code)], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr


@pytest.mark.parametrize("jobs", [1, 2, 3])
def test_results_come_in_input_order(jobs):
    items = list(range(23))
    assert list(ordered_map(lambda x: x * x, items, jobs)) == [x * x for x in items]


def test_workers_are_other_processes_that_inherit_the_callers_state():
    in_fresh_python("""
        import os
        from jaxmatch.parallel import can_fork, ordered_map
        assert can_fork()
        big = {"loaded": list(range(1000))}  # a closure over state the parent loaded: inherited, not pickled
        pids = list(ordered_map(lambda i: (os.getpid(), big["loaded"][i]), list(range(8)), 2))
        assert [v for _, v in pids] == list(range(8))
        assert os.getpid() not in {p for p, _ in pids}
    """)


@pytest.mark.parametrize("jobs", [1, 2])
def test_an_exception_surfaces_at_its_item(jobs):
    def f(x):
        if x == 3:
            raise ValueError("bad item 3")
        return x

    got = []
    with pytest.raises(ValueError, match="bad item 3"):
        for v in ordered_map(f, list(range(6)), jobs):
            got.append(v)
    assert got == [0, 1, 2]


def test_initializer_runs_in_each_worker_not_here():
    marker = []
    list(ordered_map(lambda x: x, [1, 2, 3], 1, initializer=lambda: marker.append(1)))
    assert marker == []  # no workers for jobs = 1: nothing to initialise
    assert available_cpus() >= 1


def test_warm_runs_here_and_every_item_in_the_workers():
    in_fresh_python("""
        import os
        from jaxmatch.parallel import ordered_map
        here = []
        pids = list(ordered_map(lambda i: (i, os.getpid(), len(here)), list(range(5)), 2,
                                warm=lambda: here.append(os.getpid())))
        assert here == [os.getpid()]
        assert [p[0] for p in pids] == list(range(5)) and os.getpid() not in [p[1] for p in pids]
        assert all(p[2] == 1 for p in pids)  # the workers inherit what the warm-up did
        assert list(ordered_map(lambda i: i, [7], 2, warm=lambda: 1 / 0)) == [7]  # one item: no workers, no warm-up
    """)


def test_warm_first_runs_the_first_item_here():
    in_fresh_python("""
        import os
        from jaxmatch.parallel import ordered_map
        pids = list(ordered_map(lambda i: os.getpid(), list(range(5)), 2, warm_first=True))
        assert pids[0] == os.getpid() and os.getpid() not in pids[1:]
    """)


"""scripts/milp_options.py: the integer programs of a table collected and timed both ways (the
measurement behind jaxmatch.placement.milp.FEASIBILITY_JUMP); figures only, no timing assertions."""

from __future__ import annotations

import importlib.util
import re
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent


def _script():
    spec = importlib.util.spec_from_file_location("milp_options", ROOT / "scripts" / "milp_options.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_collects_the_mesh_tables_programs_and_tabulates_both_variants(capsys):
    from jaxmatch.placement import milp

    mo = _script()
    progs = mo.collect(["mesh"])
    assert progs and all(len(args) == 7 and set(kw) == {"presolve", "time_limit"} for args, kw in progs)
    assert all(np.count_nonzero(args[4]) > 0 for args, _ in progs)  # integer programs
    assert milp._highs.__name__ == "_highs"  # the recorder is gone afterwards
    jump = milp.FEASIBILITY_JUMP
    assert mo.main(["--tables", "mesh", "--reps", "1"]) == 0
    out = capsys.readouterr().out
    counts = [int(m.group(1)) for m in re.finditer(r"^\| [0-9]+-[0-9]+ \| ([0-9]+) \| [0-9]+ \| [0-9]+ \|$", out, re.M)]
    assert out.startswith(f"{len(progs)} programs from mesh") and sum(counts) == len(progs)
    assert milp.FEASIBILITY_JUMP == jump  # the option put back

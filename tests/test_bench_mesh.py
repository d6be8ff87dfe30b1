"""scripts/bench.py --mesh: the meshing benchmark's measuring function (jaxmatch.mesh against gmsh's
quasi-structured quads) on one tiny case; figures only, no timing assertions."""

from __future__ import annotations

import importlib.util
import json
import math
import os
import subprocess
import sys
from pathlib import Path

import pytest

from jaxmatch.meshing.choose import RULES

ROOT = Path(__file__).resolve().parent.parent

pytest.importorskip("gmsh")


@pytest.fixture(scope="module")
def bench():
    spec = importlib.util.spec_from_file_location("bench", ROOT / "scripts" / "bench.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.fixture(scope="module")
def square(bench):
    return bench.bench_mesh(["square"], [16], reps=1)


@pytest.fixture(scope="module")
def frame(bench):
    return bench.bench_mesh(["square", "holes/frame"], [16], reps=1)


def test_the_regions_are_the_shapes_then_the_regions_with_holes(bench):
    names = bench.mesh_regions()
    shapes = bench.mesh_regions(holes=False)
    assert names[: len(shapes)] == shapes and "square" in shapes
    assert sorted(names[len(shapes):]) == sorted(f"holes/{p.stem}" for p in (ROOT / "examples" / "holes").glob("*.json"))


def test_a_region_with_holes_is_measured_with_its_holes(frame):
    c = frame["cases"][1]
    assert (c["shape"], c["div"], c["holes"]) == ("holes/frame", 16, 1)
    for who in ("jaxmatch", "gmsh"):
        m = c[who]
        assert m["valid"] and m["missed_corners"] == 0
        assert m["area_ratio"] == pytest.approx(1.0, abs=0.01)  # the hole's area left out of the region's
    assert c["jaxmatch"]["irregular_bound"] == 0  # a frame: 4 (1 - 1 hole) - sum (3 - valence) = 0 for a grid
    assert c["comparable"] == (0.5 <= c["gmsh"]["mean_edge_over_h"] <= 2.0)
    assert frame["cases_shapes"] == 1 and frame["cases_holes"] == 1
    assert frame["mesh_vs_gmsh_holes"] == pytest.approx(c["ratio_first"])
    assert frame["mesh_vs_gmsh_shapes"] == pytest.approx(frame["cases"][0]["ratio_first"])


def test_the_result_is_one_json_object_with_the_summary_keys(square):
    r = json.loads(json.dumps(square))
    assert {"cases", "mesh_vs_gmsh", "mesh_vs_gmsh_catalogue", "quality", "peak_rss_mb"} <= set(r)
    assert set(r["quality"]) == {"jaxmatch", "gmsh"}
    for q in r["quality"].values():
        assert {"mean_min_sj", "worst_min_sj", "irregular_per_mesh", "mean_edge_over_h", "rss_growth_mb"} <= set(q)
    assert r["mesh_vs_gmsh"] > 0 and r["peak_rss_mb"] > 0
    assert len(r["cases"]) == 1


def test_each_mesher_is_timed_and_measured(square):
    c = square["cases"][0]
    assert (c["shape"], c["div"]) == ("square", 16)
    assert c["h"] == pytest.approx(0.25)  # the unit square's perimeter / 16
    for who in ("jaxmatch", "gmsh"):
        m = c[who]
        assert {"seconds", "quads", "min_sj", "mean_sj", "irregular", "mean_edge_over_h", "valid"} <= set(m)
        assert m["seconds"] > 0 and m["quads"] > 0 and m["valid"]
        for key in ("min_sj", "mean_sj"):
            assert isinstance(m[key], float) and math.isfinite(m[key]) and -1.0 <= m[key] <= 1.0
        assert m["min_sj"] <= m["mean_sj"]
        assert isinstance(m["irregular"], int) and m["irregular"] >= 0
    for q in square["quality"].values():
        assert -1.0 <= q["worst_min_sj"] <= q["mean_min_sj"] <= 1.0
    assert c["ratio"] == pytest.approx(c["jaxmatch"]["seconds"] / c["gmsh"]["seconds"])


def test_gmsh_is_calibrated_towards_h(square):
    g = square["cases"][0]["gmsh"]
    assert g["lc_over_h"] > 0 and g["calibration"]  # tried at least once
    assert 0.5 <= g["mean_edge_over_h"] <= 2.0


def test_bulk_times_the_whole_command_and_gmsh_on_the_same_outlines(bench, monkeypatch):
    monkeypatch.setattr(bench, "MESH_BULK_REGIONS", ("examples/square.json", "examples/lshape.json"))
    r = json.loads(json.dumps(bench.mesh_bulk(divisions=8, jobs=1)))
    assert (r["regions"], r["meshed"], r["divisions"], r["jobs"]) == (2, 2, 8, 1)
    assert r["wall_s"] > 0 and r["shapes_per_s"] == pytest.approx(2 / r["wall_s"])
    assert r["gmsh"]["regions"] == 2 and r["gmsh"]["shapes_per_s"] > 0
    assert r["bulk_vs_gmsh"] == pytest.approx(r["gmsh"]["shapes_per_s"] / r["shapes_per_s"])
    assert 0 < r["per_region_s"]["median"] <= r["per_region_s"]["max"]


def test_bulk_on_random_parts_beside_another_checkout(bench):
    """--mesh-bulk-parts N --mesh-bulk-ref ROOT: the generator's parts, this checkout's command
    and the reference's alternated, each rate from its own wall time."""
    r = json.loads(json.dumps(bench.mesh_bulk(divisions=8, jobs=2, parts=3, ref=ROOT, reps=1, gmsh=False)))
    assert (r["regions"], r["meshed"], r["parts"]) == (3, 3, 3) and "gmsh" not in r
    assert r["shapes_per_s"] == pytest.approx(3 / min(r["runs_s"]))
    assert r["ref"]["shapes_per_s"] == pytest.approx(3 / min(r["ref"]["runs_s"]))
    assert r["vs_ref"] == pytest.approx(r["shapes_per_s"] / r["ref"]["shapes_per_s"])
    assert r["per_region_s"]["sum"] >= r["per_region_s"]["max"] > 0


def test_the_parts_generator_is_fixed_and_star_shaped(bench):
    import shapely

    gen = bench._script("make_bulk_parts")
    a, b = gen.parts(30), gen.parts(30)
    assert a == b and a[:10] == gen.parts(10)  # the same seed: the same parts, a prefix for fewer
    assert sum("holes" in d for d in a) == 10
    for d in a:
        outer = shapely.Polygon(d["boundary"])
        assert 5 <= len(d["boundary"]) <= 14 and outer.is_valid
    for d in a[::3]:  # the round hole sits about the centre every corner sees (star-shaped)
        outer, hole = shapely.Polygon(d["boundary"]), shapely.Polygon(d["holes"][0])
        assert len(d["holes"][0]) == gen.HOLE_POINTS and outer.contains(hole)
        c = hole.centroid
        assert all(outer.buffer(1e-9).contains(shapely.LineString([p, (c.x, c.y)])) for p in d["boundary"])


def test_the_bulk_profile_counts_every_part_and_the_strategies_that_ran(bench):
    """--mesh-bulk-profile N: the first N random parts meshed as a worker meshes them; every part
    meshed once by the Layouts strategy, each chosen mesh attributed to one kind of candidate,
    the profiled strategies within the profiled total."""
    # (in a process of its own, as the option runs: after tests that leave a process pool or a
    # cluster behind, profiling in the test process can wait forever)
    p = subprocess.run([sys.executable, str(ROOT / "scripts" / "bench.py"), "--mesh", "--mesh-bulk-profile", "3:8",
                        "--json"], capture_output=True, text=True, cwd=ROOT, timeout=300,
                       env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert p.returncode == 0, p.stderr[-2000:]
    r = json.loads(p.stdout.strip().splitlines()[-1])["bulk_profile"]
    assert (r["parts"], r["div"]) == (3, 8) and r["cpu_s"] > 0
    assert r["cpu_s_per_part"] == pytest.approx(r["cpu_s"] / 3)
    assert r["strategies"]["Layouts"]["parts"] == 3 and sum(r["chosen_by"].values()) == 3
    ran = [v["profiled_s"] for v in r["strategies"].values()]
    assert all(s >= 0 for s in ran) and sum(ran) <= r["profiled_s"] * 1.01
    st = r["strategies"].values()  # each chosen mesh made by a strategy that ran; unchosen time is some of its time
    assert sum(v["chosen"] for v in st) >= 3 and all(v["chosen"] <= v["parts"] for v in st)
    assert all(0 <= v["unchosen_cpu_s"] <= v["cpu_s"] for v in st) and sum(v["cpu_s"] for v in st) <= r["cpu_s"] + 1e-9
    assert all(v["cpu_s"] == 0 for v in st if v["parts"] == 0)
    assert all(0 <= v["bounded"] <= v["parts"] - v["chosen"] for v in st)  # a bound never rules out a winner
    # a call that meshed no candidate is one of the losing calls; Layouts meshes one in every part
    assert all(0 <= v["empty"] <= v["parts"] - v["chosen"] and 0 <= v["empty_cpu_s"] <= v["unchosen_cpu_s"] + 1e-12
               for v in st)
    assert r["strategies"]["Layouts"]["empty"] == 0
    assert len(r["top"]) == len(r["top_own"]) > 0 and r["top"][0][3] >= r["top"][-1][3]
    assert r["top"][0][1] >= 3  # the outermost entry: at least one call per part
    lay = r["layouts"]  # every part meshes one layout at least; the losers are some of them, under a rule
    assert lay["meshed"] >= 3 and 0 < lay["cpu_s"] <= r["cpu_s"]
    assert set(lay["after_better"]) <= set(RULES)
    assert sum(v["layouts"] for v in lay["after_better"].values()) < lay["meshed"]
    assert sum(v["cpu_s"] for v in lay["after_better"].values()) <= lay["cpu_s"] + 1e-9


@pytest.mark.parametrize("region", ["examples/lshape.json", "examples/holes/plate-bolt.json"])
def test_the_layout_losers_are_the_layouts_that_lost_to_an_earlier_one(bench, region):
    """_layout_losers: every candidate that the layout strategies meshed is counted once (not the
    larger or conforming templates), and of them at most all but the first are losers, each
    under a rule of the choice."""
    import jaxmatch

    shp = jaxmatch.load_shape(ROOT / region)
    bench.clear_mesh_caches()
    with bench._layout_losers() as lay:
        m = jaxmatch.mesh(shp, divisions=16)
    layouts = [c for c in m.tried if c.mesh is not None and " " not in c.name]
    assert lay["meshed"] == len(layouts) and lay["cpu_s"] > 0
    lost = sum(v["layouts"] for v in lay["after_better"].values())
    assert lost <= len(layouts) - 1  # (the first layout meshed has nothing before it)
    assert set(lay["after_better"]) <= set(RULES)


def test_the_profile_bound_rules_out_the_rings_only_after_a_mesh_they_cannot_beat(bench):
    """_bounded: nothing meshed, no claim; after the square's single grid (min scaled Jacobian
    1, at the size), the ring layout (more patches, at best as good) cannot win, and the
    decompositions, which have no bound there, are never ruled out."""
    import time

    import jaxmatch
    from jaxmatch.meshing import strategies
    from jaxmatch.meshing.region import canonical, corner_points
    from jaxmatch.defaults import DEFAULT_LATTICE, QUALITY
    from jaxmatch.inputs import _lattice

    shp = jaxmatch.load_shape(ROOT / "examples" / "square.json")
    cat = jaxmatch.load_catalogue()
    m = jaxmatch.mesh(shp, divisions=32, catalogue=cat)  # (at P/16 no ring fits the unit square)
    assert m.chosen == "single" and m.min_scaled_jacobian == pytest.approx(1.0)
    h = m.size
    region = canonical(shp, h, jaxmatch.shape.DEFAULT_CORNER_ANGLE)
    req = strategies.Request(region, cat, _lattice(DEFAULT_LATTICE), h, corner_points(region), QUALITY, None,
                             time.perf_counter(), None)
    single = [c for c in m.tried if c.name == "single"]
    assert not bench._bounded(strategies.RingPartition, req, [])
    assert bench._bounded(strategies.RingPartition, req, single)
    assert not bench._bounded(strategies.Layouts, req, single)

"""Compiled code and its registry: the bottom floor of the package.

Nothing here imports from ``scoring``, ``placement``, ``meshing``, ``io``, ``catalogue`` or the CLI;
only numpy, numba, JAX, the standard library, :mod:`jaxmatch.errors` and :mod:`jaxmatch.lazy`. The environment
variables that choose a kernel are read here and nowhere else: ``JAXMATCH_BACKEND``
(:func:`jaxmatch.kernels.backends.default_backend`; it also reads ``JAX_PLATFORMS``) and
``JAXMATCH_PLACEMENT_KERNELS`` (:data:`jaxmatch.kernels.placement.BACKEND`).

Files
-----
=====================  ============================================================================
``problem.py``         the scoring DP's contract: ``DPProblem``, ``DPKind``, ``Backend``, ``run_calls``
``model.py``           the scoring model ``Weights`` (match table, skip weights), ``NEG``, the shifted frame
``backends.py``        the scoring DP's CPU kernels and the choice among them; ``c_align``
``_dp.c``              C: ``jm_dp_i16`` (the DP of many meshes), ``jm_align_f32`` (one orientation)
``dp_numba.py``        numba: the DP of many meshes on every core
``dp_xla.py``          JAX: ``final_blocks`` (the XLA kernel), ``dp_scan`` (any reduction)
``placement.py``       the placement kernels (smoothing, Tutte, alignment DPs, quality), through ctypes
``_placement.c``       C: those kernels
``_numba_smooth.py``   numba: the smoother and dense Tutte, where ``_placement.c`` was not built
``reference.py``       plain Python: brute force and the plain DP (the tests' oracle)
=====================  ============================================================================

One kernel per role
-------------------
Role -> implementation (file). "Fallback" is what runs where the C library was not built (the
C extensions are optional: the README asks only for ``python3`` and PyPI).

* **Scoring DP** (best utility of every orientation of many meshes, :func:`jaxmatch.scoring.exact.exact_values`):

  - small CPU problems (the pruned search's few million cells): C ``jm_dp_i16`` through
    ``backends.c_values`` (``_dp.c``; loads in milliseconds); fallback numpy ``backends.numpy_values``;
  - large CPU problems: numba ``dp_numba.dp_kernel_i16`` through ``backends.NumbaBackend``
    (int16 lanes, ``prange`` over the cores; importing numba costs ~0.45 s, so it runs once the
    process has spent ``backends.NUMPY_CELLS`` cells in the light kernel);
  - GPU / XLA (``JAXMATCH_BACKEND=xla``, accelerators, int32 / float32 models): ``dp_xla.final_blocks``
    through ``dp_xla.CPUBackend``; over several devices ``jaxmatch.scoring.bulk.ShardedBackend``
    runs the same blocks;
  - gradients: ``dp_xla.dp_scan`` with the smoothed maximum of :mod:`jaxmatch.scoring.soft`
    (lattice tuning);
  - oracle: ``reference.dp_reference`` (plain DP), ``reference.brute_force`` and
    ``brute_force_soft`` (every alignment enumerated).

* **One orientation's alignment** (the DP rows and their backtrack, :func:`jaxmatch.scoring.exact.align`):
  C ``jm_align_f32`` through ``backends.c_align``; fallback and oracle numpy
  :func:`jaxmatch.scoring.exact.dp_rows` (tested bit for bit against ``dp_scan(keep_rows=True)``).

* **Placement** (:mod:`jaxmatch.placement.embed`, :mod:`jaxmatch.placement.choose`): C through
  ``placement`` (``_placement.c``); the oracle of each is the numpy version in the caller
  (``reference=True``). Fallback: the smoother and dense Tutte in numba (``_numba_smooth.py``),
  the alignment DPs, the spread programme and the per-quad quality in the callers' numpy.

Every copy of the LCS recurrence
--------------------------------
``D[i][j] = max(D[i-1][j] + skip[code[i-1]], D[i-1][j-1] + W[i-1, j-1])`` (the paper's modified
LCS, skip weights included; most copies run it in the shifted frame of
:mod:`jaxmatch.scoring.exact`). Each copy, and why it exists:

1. ``_dp.c`` ``jm_dp_i16``: small CPU problems without numba's start-up; bit for bit the numba kernel.
2. ``dp_numba.py`` ``_chunk``: large CPU problems on every core.
3. ``backends.py`` ``numpy_values``: small problems where ``_dp.c`` was not built, and int32 /
   float32 models within the light kernel's budget (any number type).
4. ``dp_xla.py`` ``_final_block``: the XLA kernel (GPUs, TPUs, ``JAXMATCH_BACKEND=xla``,
   wide models, sharded bulk runs).
5. ``dp_xla.py`` ``dp_scan``: any reduction; the soft maximum gives the gradients of tuning.
6. ``_dp.c`` ``jm_align_f32``: one orientation's float32 rows and backtrack (every ranked match).
7. ``scoring/exact.py`` ``dp_rows``: the same in numpy, fallback and oracle of 6.
8. ``reference.py`` ``dp_reference``: the tests' oracle, plain Python, unshifted, ``-inf`` as is.
9. ``placement/spread.py`` ``orientation_utilities(reference=True)``: numpy, float64, unshifted,
   every orientation of one mesh with the lattice's own (possibly fractional) weights, whose best
   values ``match_candidates`` compares with ``==``; the fallback and oracle of 10.
10. ``_placement.c`` ``jm_orientation_utilities``: 9 compiled (per candidate mesh of a placement,
    microseconds, no padding or number-type choice as the scoring host makes).

Different recurrences, not copies of it: the spread DPs (``spread.spread_optimal_alignment`` and
``_spread_forward`` in numpy, ``_placement.c`` ``jm_candidates``: best utility with the skip
weights of the points between consecutive vertices, then least squared arc-length gap, per
orientation; ``spread.spread_alignment`` and ``jm_spread``: least squared gap at fixed point
codes) and ``scoring/bulk.py`` ``upper_bounds`` (a bound from triple histograms, no DP).

Dropped: ``_numba_spread.py``, the numba copy of 10 (the recurrence's eleventh copy) and of
``jm_candidates``. Measured on the 118 meshes of ``scripts/snapshot_meshes`` (every example
region at P/16 and P/32, one ``jaxmatch mesh`` process each) with the placement kernels forced:
numba smoothing with the alignment DPs in numpy took 165.2 s against 163.3 s with both in numba
(alternated region by region; the same 118 files byte for byte), so that copy bought nothing.
The smoother's numba copy stays: in numpy its L-BFGS loop is 10 to 14 times numba's time on
holes and long outlines (figures and commands: :mod:`jaxmatch.kernels.placement`).
"""

"""The thread policy of a run (ntncontact.threads): who threads, how many, and NumPy's BLAS
kept serial while a run steps."""

from __future__ import annotations

import os
from pathlib import Path

import numba
import numpy as np
import pytest

import ntncontact
from ntncontact import threads
from ntncontact.fem.kernels_numba import MIN_ELEMENTS_PER_THREAD, NumbaAssembly
from ntncontact.solvers import linear

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def strip_cells(n_elements: int) -> np.ndarray:
    """Q4 cells of a strip of n_elements x 1 elements."""
    lower = np.arange(n_elements)
    return np.column_stack([lower, lower + 1, lower + n_elements + 2, lower + n_elements + 1])


def test_run_threads_follow_the_machine_and_omp_num_threads(monkeypatch):
    monkeypatch.delenv("OMP_NUM_THREADS", raising=False)
    assert threads.run_threads(1) == 1
    assert threads.run_threads(2) == 2
    assert threads.run_threads(64) == threads.MAX_THREADS
    assert threads.run_threads() == min(threads.available_cores(), threads.MAX_THREADS)
    monkeypatch.setenv("OMP_NUM_THREADS", "3")
    assert threads.run_threads(64) == 3
    monkeypatch.setenv("OMP_NUM_THREADS", "")  # empty: not set
    assert threads.run_threads(2) == 2


def test_assembly_threads_default_to_the_runs_within_the_elements_and_numba(monkeypatch):
    monkeypatch.setenv("OMP_NUM_THREADS", "2")
    large = strip_cells(4 * MIN_ELEMENTS_PER_THREAD)
    expected = min(2, numba.get_num_threads())
    assert NumbaAssembly("neo_hookean", large, np.arange(len(large))).threads == expected
    # fewer than MIN_ELEMENTS_PER_THREAD elements a thread: the serial loop
    small = strip_cells(2 * MIN_ELEMENTS_PER_THREAD - 1)
    assert NumbaAssembly("neo_hookean", small, np.arange(len(small))).threads == 1
    monkeypatch.setenv("OMP_NUM_THREADS", "1")  # as in a Dask worker
    assert NumbaAssembly("neo_hookean", large, np.arange(len(large))).threads == 1
    assert NumbaAssembly("neo_hookean", large, np.arange(len(large)), threads=1).threads == 1


def test_a_run_steps_with_numpys_blas_on_one_thread_and_restores_it():
    """Every step (and every observer) sees the BLAS on one thread; after the run the caller's
    setting is back. Set to 2 first, so that the test can fail on a 1-thread default."""
    blas = threads._blas()
    if not blas.info():
        pytest.skip("no BLAS library seen by threadpoolctl")
    seen = []
    scenario = ntncontact.load_scenario(EXAMPLES / "spinning_block.toml", ["analysis.t_end=0.1"])
    with blas.limit(limits=2):
        before = [lib["num_threads"] for lib in blas.info()]
        ntncontact.run(scenario, progress=lambda t: seen.append(
            [lib["num_threads"] for lib in blas.info()]))
        after = [lib["num_threads"] for lib in blas.info()]
    assert len(seen) == 5 and all(step == [1] * len(before) for step in seen)
    assert after == before


def test_a_sweeps_case_runs_on_one_thread_in_every_part(monkeypatch):
    """single_threaded (a sweep's case): PARDISO and the assembly get 1 thread even where
    nothing set the environment (a worker not started by a Dask nanny); restored after."""
    monkeypatch.delenv("OMP_NUM_THREADS", raising=False)
    monkeypatch.setenv("MKL_NUM_THREADS", "2")
    large = strip_cells(4 * MIN_ELEMENTS_PER_THREAD)
    with threads.single_threaded():
        assert linear.pardiso_threads(16) == 1
        assert NumbaAssembly("neo_hookean", large, np.arange(len(large))).threads == 1
        assert all(lib["num_threads"] == 1 for lib in threads._blas().info())
    assert "OMP_NUM_THREADS" not in os.environ
    assert os.environ["MKL_NUM_THREADS"] == "2"


ORDER_SCRIPT = """
import hashlib, sys
from pathlib import Path
if sys.argv[1] == "pypardiso_first":  # a script that imports pypardiso itself first
    import pypardiso  # noqa: F401  (it loads mkl_rt at its import)
if sys.argv[1] == "pypardiso_second":  # ... or right after ntncontact
    import ntncontact
    import pypardiso  # noqa: F401,F811
if sys.argv[1] == "pardiso_first":  # as a script or test that asks for PARDISO first
    from ntncontact.solvers.linear import pardiso_available
    assert pardiso_available()
import ntncontact as ntc
from threadpoolctl import threadpool_info
scenario = ntc.load_scenario(Path(sys.argv[2]), {
    "analysis.t_end": 0.02, "bodies.0.mesh.n_radial": 16, "bodies.0.mesh.n_circ": 192,
    "bodies.1.mesh.nx": 160, "bodies.1.mesh.ny": 16})  # 12 002 unknowns: PARDISO
result = ntc.run(scenario, Path(sys.argv[3]))
layers = {i.get("threading_layer") for i in threadpool_info() if i["internal_api"] == "mkl"}
print(result.history.to_numpy().tobytes().hex(), *sorted(layers))
"""


@pytest.mark.skipif(not linear.pardiso_available(), reason="pypardiso not installed")
def test_a_run_does_not_depend_on_whether_pardiso_or_the_kernels_load_first(tmp_path):
    """MKL picks its OpenMP layer when it loads: Intel's after a script asked for PARDISO
    first, GNU after Numba's kernels had run. The two gave other bits (so a run begun in
    Python and restarted by the command line differed); the package pins GNU
    (``linear._pin_mkl_threading_layer``) and both orders give the same history. Fresh
    processes on the default threads (no OMP_NUM_THREADS, which ``make test`` sets). A script
    that imported pypardiso itself first (mkl_rt loaded before the pin) ran on Intel's layer
    beside Numba's GNU one until the layer was also selected in the loaded library
    (``linear._select_threading_layer``): other bits, and ~30 % more CPU."""
    import subprocess
    import sys

    env = {k: v for k, v in os.environ.items()
           if k not in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "MKL_THREADING_LAYER")}
    outputs = []
    orders = ("pardiso_first", "kernels_first", "pypardiso_first", "pypardiso_second")
    for order in orders:
        done = subprocess.run(
            [sys.executable, "-c", ORDER_SCRIPT, order, str(EXAMPLES / "ring_impact.toml"),
             str(tmp_path / order)], env=env, capture_output=True, text=True, timeout=600)
        assert done.returncode == 0, done.stderr[-2000:]
        outputs.append(done.stdout.split())
    histories = [history for history, *_ in outputs]
    assert [layers for _, *layers in outputs] == [["gnu"]] * len(orders)
    assert histories[1:] == histories[:1] * (len(orders) - 1)


@pytest.mark.skipif(not linear.pardiso_available(), reason="pypardiso not installed")
def test_an_mkl_already_used_before_ntncontact_is_named_in_a_warning():
    """Once MKL has run, its threading layer is fixed: the package cannot select GNU's and
    says so, rather than letting the run differ from the command line's in silence."""
    import subprocess
    import sys

    script = (
        "import warnings, pypardiso\n"
        "pypardiso.ps.libmkl.MKL_Get_Max_Threads()  # any MKL call fixes the layer\n"
        "with warnings.catch_warnings(record=True) as caught:\n"
        "    warnings.simplefilter('always')\n"
        "    import ntncontact.solvers.linear\n"
        "print([str(w.message) for w in caught if w.category is RuntimeWarning])\n")
    env = {k: v for k, v in os.environ.items() if k != "MKL_THREADING_LAYER"}
    done = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True,
                          text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    assert "MKL already runs on its INTEL threading layer" in done.stdout
    assert "MKL_THREADING_LAYER=GNU" in done.stdout

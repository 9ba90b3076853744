"""ntncontact.warmup: its two small runs reach the kernels they are meant to compile."""

import os
import re
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np

import ntncontact
from ntncontact import warmup
from ntncontact.fem.kernels_numba import cell_fields
from ntncontact.jit import COMPILE_NOTE
from ntncontact.warmup import exercise


def test_lagrangian_group_makes_contact_and_computes_a_frames_fields():
    sim = exercise(ale=False)
    assert sum(len(c) for c in sim.state.contact) > 0  # the contact kernel ran
    assert not sim.model.ale_bodies
    assert cell_fields.signatures  # the output's kernel was compiled (or loaded) too


def test_ale_group_moves_the_mesh_and_remaps_the_fields():
    sim = exercise(ale=True)
    setup = sim.model.ale_bodies[0]
    rows = slice(setup.node_offset, setup.node_offset + setup.n_nodes)
    # the ALE obstacle's nodes carry other particles than at the start: the mesh slid and the
    # fields were remapped (the kernels the warm-up is for)
    assert np.abs(sim.state.X[rows] - sim.model.X0[rows]).max() > 1e-4


# ----------------------------------------------------------------------------------------------
# Where the compiled kernels live, and the note a run that compiles prints
# ----------------------------------------------------------------------------------------------
PROBE = '''
from ntncontact.jit import njit

@njit(cache=True)
def twice(x):
    return 2.0 * x

@njit(cache=True)
def thrice(x):
    return 3.0 * x
'''


def _python(code: str, env: dict[str, str], cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", textwrap.dedent(code)], capture_output=True,
                          text=True, timeout=300, env=env, cwd=cwd)


def _clean_env(**extra: str) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    return env | extra


def test_a_process_that_compiles_says_so_once_and_the_next_one_loads_the_cache(tmp_path):
    """Two kernels of the package (a probe module placed in the package) compiled into an empty
    cache folder: the note once on stderr; a second process loads them and says nothing."""
    (tmp_path / "probe").mkdir()
    (tmp_path / "probe" / "_kernel_probe.py").write_text(PROBE)
    cache = tmp_path / "cache"
    code = f"""
        import ntncontact
        ntncontact.__path__.append({str(tmp_path / "probe")!r})
        from ntncontact._kernel_probe import thrice, twice
        print(twice(1.5) + thrice(1.0))
    """
    env = _clean_env(NUMBA_CACHE_DIR=str(cache))
    first = _python(code, env, tmp_path)
    assert first.returncode == 0, first.stderr
    assert first.stdout.strip() == "6.0"
    note = COMPILE_NOTE.format(directory=cache)
    assert first.stderr.splitlines().count(note) == 1, first.stderr
    assert list(cache.rglob("_kernel_probe.*.nbi"))  # the index files of both kernels
    second = _python(code, env, tmp_path)
    assert second.returncode == 0 and second.stdout.strip() == "6.0"
    assert "compiling kernels" not in second.stderr, second.stderr


def test_the_package_chooses_the_cache_folder_unless_the_user_did(tmp_path):
    """Without NUMBA_CACHE_DIR: the user's cache folder (XDG_CACHE_HOME here), also when numba
    was imported before the package; with it: the user's choice."""
    code = """
        import numba
        import ntncontact
        print(numba.config.CACHE_DIR)
        print(ntncontact.kernel_cache_dir())
    """
    xdg = tmp_path / "xdg"
    chosen = _python(code, _clean_env(XDG_CACHE_HOME=str(xdg)), tmp_path)
    assert chosen.returncode == 0, chosen.stderr
    assert chosen.stdout.split() == [str(xdg / "ntncontact" / "numba")] * 2
    own = _python(code, _clean_env(NUMBA_CACHE_DIR=str(tmp_path / "mine")), tmp_path)
    assert own.stdout.split() == [str(tmp_path / "mine")] * 2


def test_every_kernel_module_compiles_through_the_package_decorator():
    """The note and the cache folder hold for every kernel: no module decorates with numba's
    njit directly."""
    source = Path(ntncontact.__file__).parent
    direct = [str(p.relative_to(source)) for p in source.rglob("*.py")
              if re.search(r"^from numba import .*\bnjit\b|numba\.njit\(|@numba\.jit",
                           p.read_text(), re.MULTILINE) and p.name != "jit.py"]
    assert direct == []


def test_the_threaded_group_assembles_on_several_threads_where_runs_do(monkeypatch):
    """An independent tester's first run of 10^4 elements compiled the threaded assembly
    (18-23 s inside its wall_time_s) although make had run the warm-up: the warm-up now runs a
    block just large enough for it wherever runs use several threads."""
    from ntncontact.fem import kernels_numba

    calls = []
    real = kernels_numba.assemble_blocks
    monkeypatch.setattr(kernels_numba, "assemble_blocks",
                        lambda *args: calls.append(1) or real(*args))
    if warmup.run_threads() < 2:  # a 1-core machine: runs never thread, nothing to compile
        assert warmup.compile_threaded_assembly() == 0.0 and not calls
        return
    assert warmup.compile_threaded_assembly() > 0.0 and calls

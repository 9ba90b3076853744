"""Start-up of the command: modules loaded only when used, bytecode written by the warm-up."""

import importlib.util
import subprocess
import sys
import textwrap
from pathlib import Path

from ntncontact.warmup import compile_bytecode


def _python(code: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", textwrap.dedent(code)], capture_output=True,
                          text=True, timeout=120)


def test_deferred_numpy_modules_load_at_first_use_only():
    """scipy.sparse's import no longer runs numpy.f2py and numpy.testing; they still work
    when used, and modules already imported are left alone."""
    done = _python("""
        import sys
        from ntncontact.cli import UNUSED_NUMPY_MODULES, defer_imports
        import numpy.ma
        assert defer_imports(UNUSED_NUMPY_MODULES + ("numpy.ma",)) == list(UNUSED_NUMPY_MODULES)
        import scipy.sparse
        import numpy
        lazy = [n for n in UNUSED_NUMPY_MODULES if type(sys.modules[n]).__name__ != "module"]
        assert lazy == list(UNUSED_NUMPY_MODULES), lazy
        assert "numpy.f2py.crackfortran" not in sys.modules
        from numpy.testing import assert_array_equal  # loads it now
        assert_array_equal(numpy.arange(3), [0, 1, 2])
        assert callable(numpy.f2py.run_main) and "numpy.f2py.crackfortran" in sys.modules
        print("ok")
    """)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "ok"


def test_compile_bytecode_writes_it_even_where_python_would_not(tmp_path, monkeypatch):
    package = tmp_path / "pkg"
    package.mkdir()
    module = package / "mod.py"
    module.write_text("VALUE = 1\n")
    monkeypatch.setattr(sys, "dont_write_bytecode", True)
    assert compile_bytecode(package)
    cached = importlib.util.cache_from_source(str(module))
    assert Path(cached).is_file() and Path(cached).parent == package / "__pycache__"

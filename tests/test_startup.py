"""Start-up and exit of the command; bytecode written by the warm-up."""

import importlib.util
import subprocess
import sys
import textwrap
from pathlib import Path

from ntncontact.warmup import compile_bytecode


def _python(code: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", textwrap.dedent(code)], capture_output=True,
                          text=True, timeout=120)


def test_the_command_ends_through_the_interpreters_normal_exit(tmp_path):
    """console_main returns main's exit code through sys.exit: atexit handlers run and
    buffered output (a pipe here) arrives whole."""
    marker = tmp_path / "atexit_ran"
    done = _python(f"""
        import atexit, pathlib, sys
        atexit.register(pathlib.Path({str(marker)!r}).write_text, "yes")
        sys.argv = ["ntncontact", "compare", {str(tmp_path / "missing")!r}]
        from ntncontact.cli import console_main
        console_main()
    """)
    assert done.returncode == 1 and "error" in done.stderr, done.stderr
    assert "Traceback" not in done.stderr
    assert marker.read_text() == "yes"


def test_compile_bytecode_writes_it_even_where_python_would_not(tmp_path, monkeypatch):
    package = tmp_path / "pkg"
    package.mkdir()
    module = package / "mod.py"
    module.write_text("VALUE = 1\n")
    monkeypatch.setattr(sys, "dont_write_bytecode", True)
    assert compile_bytecode(package)
    cached = importlib.util.cache_from_source(str(module))
    assert Path(cached).is_file() and Path(cached).parent == package / "__pycache__"

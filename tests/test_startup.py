"""Start-up and exit of the command; bytecode written by the warm-up."""

import importlib.metadata
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
        from ntncontact_command import console_main
        console_main()
    """)
    assert done.returncode == 1 and "error" in done.stderr, done.stderr
    assert "Traceback" not in done.stderr
    assert marker.read_text() == "yes"


def test_the_installed_command_starts_from_the_guarded_entry_point():
    (script,) = [entry for entry in importlib.metadata.entry_points(group="console_scripts")
                 if entry.name == "ntncontact"]
    assert script.value == "ntncontact_command:console_main"


def test_a_ctrl_c_while_the_package_imports_ends_in_one_line():
    """The SIGINT is sent from inside the import of the command (an import hook), so it
    lands there every time; it used to end in a KeyboardInterrupt traceback."""
    done = _python("""
        import os, signal, sys
        class InterruptTheImport:
            def find_spec(self, name, path=None, target=None):
                if name == "ntncontact.cli":
                    os.kill(os.getpid(), signal.SIGINT)
                return None
        sys.meta_path.insert(0, InterruptTheImport())
        sys.argv = ["ntncontact", "run", "missing.toml"]
        from ntncontact_command import console_main
        console_main()
    """)
    assert done.returncode == 130, done.stderr
    assert done.stderr == "interrupted while starting: nothing was run or written\n"


def test_a_broken_installation_is_named_without_a_traceback():
    done = _python("""
        import sys
        sys.modules["ntncontact.cli"] = None  # what a missing module looks like to import
        sys.argv = ["ntncontact", "--version"]
        from ntncontact_command import console_main
        console_main()
    """)
    assert done.returncode == 1 and "Traceback" not in done.stderr, done.stderr
    assert "installation is incomplete" in done.stderr and "reinstall" in done.stderr


def test_compile_bytecode_writes_it_even_where_python_would_not(tmp_path, monkeypatch):
    package = tmp_path / "pkg"
    package.mkdir()
    module = package / "mod.py"
    module.write_text("VALUE = 1\n")
    monkeypatch.setattr(sys, "dont_write_bytecode", True)
    assert compile_bytecode(package)
    cached = importlib.util.cache_from_source(str(module))
    assert Path(cached).is_file() and Path(cached).parent == package / "__pycache__"

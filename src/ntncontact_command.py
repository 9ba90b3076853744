"""The ``ntncontact`` command's entry point.

It lives outside the package on purpose: importing ``ntncontact`` loads NumPy, SciPy, Numba
and the kernels (1-2 s), and a Ctrl-C in that time used to end in a traceback, since the
command's own handling (``ntncontact.cli.main``) did not exist yet. Here the import itself is
guarded, and so is a broken installation.
"""

import sys

INTERRUPTED = 130  # 128 + SIGINT, as the command's other interrupts


def console_main() -> None:
    """Import the command, then run it; its return value is the exit code."""
    try:
        from ntncontact.cli import main
    except KeyboardInterrupt:
        print("interrupted while starting: nothing was run or written", file=sys.stderr)
        sys.exit(INTERRUPTED)
    except ImportError as err:
        print(f"error: ntncontact cannot start, its installation is incomplete ({err}); "
              "reinstall it (make demo, or pip install ntncontact)", file=sys.stderr)
        sys.exit(1)
    sys.exit(main())


if __name__ == "__main__":  # pragma: no cover
    console_main()

"""The ``ntncontact`` command's entry point.

It lives outside the package on purpose: importing ``ntncontact`` loads NumPy, SciPy, Numba
and the kernels (1-2 s), and a Ctrl-C in that time used to end in a traceback, since the
command's own handling (``ntncontact.cli.main``) did not exist yet. Here the import itself is
guarded, and so is a broken installation.
"""

import signal
import sys

INTERRUPTED = 130  # 128 + SIGINT, as the command's other interrupts


def _terminated(signum: int, frame: object) -> None:
    """SIGTERM while starting: as a Ctrl-C (a tester's SIGTERM 0.5 s after the start ended the
    command at 143 without a word, while SIGINT said that nothing was run)."""
    raise KeyboardInterrupt(signal.Signals(signum).name)


def console_main() -> None:
    """Import the command, then run it; its return value is the exit code."""
    previous = signal.signal(signal.SIGTERM, _terminated)
    try:
        from ntncontact.cli import main
    except KeyboardInterrupt as err:
        print("interrupted while starting: nothing was run or written", file=sys.stderr)
        sys.exit(128 + signal.SIGTERM if str(err) == "SIGTERM" else INTERRUPTED)
    except ImportError as err:
        print(f"error: ntncontact cannot start, its installation is incomplete ({err}); "
              "reinstall it (make demo, or pip install ntncontact)", file=sys.stderr)
        sys.exit(1)
    finally:
        if previous is not None:  # None: a handler not set from Python, left as it is
            signal.signal(signal.SIGTERM, previous)  # the commands install their own
    sys.exit(main())

if __name__ == "__main__":  # pragma: no cover
    console_main()

"""Per-call time of the contact evaluation: compiled kernel against the NumPy reference.

Usage: .venv/bin/python benchmarks/contact_eval.py [--pairs 7 100] [--repeats 7]

Times :func:`ntncontact.contact.evaluate_contact` (force, COO tangent and per-pair results) on
two wavy node-to-node surfaces with P active pairs, frictionless persistency law (the ring
impact's setting) and Coulomb friction under the gap law, against its NumPy oracle
(tests/contact_reference.py, the same formulas with whole-array operations). Reports the median
over repeats of the mean time per call, after checking that both agree. The first call in a
fresh process (Numba cache loaded or compiled) is measured in subprocesses, with the project's
cache and with an empty one.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from dataclasses import replace

import numpy as np

from ntncontact.contact import ContactLaw, ContactSurface, Interface, PairState, evaluate

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "tests"))
import contact_reference  # noqa: E402  (the tests' oracle)

#: the timed implementations: the NumPy oracle and the compiled kernel
IMPLEMENTATIONS = {"numpy": contact_reference.evaluate_contact,
                   "numba": evaluate.evaluate_contact}


def configuration(pairs: int, seed: int = 0):
    """Surface 1 (pairs + 2 nodes, open) above surface 2 (walking back), pairs node to node."""
    rng = np.random.default_rng(seed)
    n = pairs + 2
    base = np.linspace(0.0, 1.0, n)
    x1 = np.column_stack((base, np.full(n, -0.01))) + 0.002 * rng.standard_normal((n, 2))
    x2 = np.column_stack((base, np.zeros(n))) + 0.002 * rng.standard_normal((n, 2))
    x = np.vstack((x1, x2))
    v = np.vstack((np.tile([0.3, -1.0], (n, 1)), np.zeros((n, 2)))) + 0.05 * rng.standard_normal(
        (2 * n, 2))
    interface = Interface(ContactSurface(np.arange(n)), ContactSurface(np.arange(2 * n - 1, n - 1,
                                                                                 -1)))
    node1 = np.arange(1, pairs + 1)
    state = PairState.from_pairs(np.column_stack((node1, 2 * n - 1 - node1)))
    state = replace(state, lambda_N=rng.uniform(0.0, 2.0, pairs),
                    t_T=rng.normal(0.0, 0.5, pairs))
    return x, v, interface, state


def cases(pairs: int):
    """(name, args, kwargs) of evaluate_contact per setting."""
    x, v, interface, state = configuration(pairs)
    ring = ContactLaw("augmented_lagrangian", eps_N=1000.0)
    coulomb = ContactLaw("augmented_lagrangian", eps_N=1000.0, eps_T=500.0, mu=0.3)
    return [
        ("frictionless, rate law", (x, v, 400.0, interface, state, ring), {"dt": 0.005}),
        ("Coulomb, gap law", (x, None, None, interface, state, coulomb), {"x_start": x - 0.003}),
    ]


def per_call(kernel: str, args, kwargs, repeats: int) -> float:
    """Median over ``repeats`` of the mean time of one call (seconds)."""
    evaluate_contact = IMPLEMENTATIONS[kernel]
    evaluate_contact(*args, **kwargs)
    number = 200
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        for _ in range(number):
            evaluate_contact(*args, **kwargs)
        times.append((time.perf_counter() - start) / number)
    return statistics.median(times)


def agree(args, kwargs) -> float:
    """Largest difference of force and tangent between the kernels, relative."""
    fast = IMPLEMENTATIONS["numba"](*args, **kwargs)
    ref = IMPLEMENTATIONS["numpy"](*args, **kwargs)
    dk = abs(fast.tangent_matrix() - ref.tangent_matrix()).max() / abs(ref.vals).max()
    df = np.abs(fast.force - ref.force).max() / np.abs(ref.force).max()
    return float(max(dk, df))


_FIRST_CALL = """
import time
t0 = time.perf_counter()
import sys; sys.path.insert(0, {here!r})
from contact_eval import cases
from ntncontact.contact import evaluate
name, args, kwargs = cases(7)[0]
t1 = time.perf_counter()
evaluate.evaluate_contact(*args, **kwargs)
t2 = time.perf_counter()
print(f"{{t2 - t1:.3f}}")
"""


def first_call(cache_dir: str | None) -> float:
    """Seconds of the first compiled call in a fresh interpreter (imports excluded)."""
    env = dict(os.environ)
    if cache_dir is not None:
        env["NUMBA_CACHE_DIR"] = cache_dir
    code = _FIRST_CALL.format(here=os.path.dirname(os.path.abspath(__file__)))
    out = subprocess.run([sys.executable, "-c", code], env=env, check=True,
                         capture_output=True, text=True)
    return float(out.stdout.strip().splitlines()[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--pairs", type=int, nargs="+", default=[7, 100])
    parser.add_argument("--repeats", type=int, default=7)
    opts = parser.parse_args()
    print("| pairs | setting | NumPy us/call | Numba us/call | speed-up | max rel. diff |")
    print("| ---: | --- | ---: | ---: | ---: | ---: |")
    for p in opts.pairs:
        for name, args, kwargs in cases(p):
            ref = per_call("numpy", args, kwargs, opts.repeats)
            fast = per_call("numba", args, kwargs, opts.repeats)
            print(f"| {p} | {name} | {1e6 * ref:.1f} | {1e6 * fast:.1f} | {ref / fast:.1f}x | "
                  f"{agree(args, kwargs):.1e} |")
    cached = statistics.median(first_call(None) for _ in range(3))
    with tempfile.TemporaryDirectory() as empty:
        cold = first_call(empty)
    print(f"\nfirst call in a fresh process: {cached:.2f} s with the Numba cache, "
          f"{cold:.1f} s compiling (empty cache)")


if __name__ == "__main__":
    main()

"""The warm-up compiles what ordinary runs use: after its two small runs, a run of another
common configuration calls no kernel with an argument type the warm-up did not.

Numba compiles a kernel once per argument type (a read-only array is another type than a
writable one, a stride-0 view another than a contiguous array). Testers saw the compile note
again after ``make``: the first run with an ALE annulus compiled ``slide_chain`` (~10 s) since a
closed chain's arrays were writable where an open chain's are the mesh's frozen ones; the ALE
examples whose interior nodes move compiled ``_inverse_bilinear`` again (~1.2 s) for a read-only
broadcast view.

The test compares signatures, not compile events: a signature one earlier run compiled sits in
the on-disk cache from then on and is loaded without a compile event, so a listener would pass
on any machine that had once run the configuration. It runs in a fresh process so that the
kernels this worker's other tests loaded do not count: ~5 s with the warm cache make test
starts from (~2.5 min in an empty one, which compiles everything).
"""

import json
import subprocess
import sys
import textwrap

CODE = '''
import json, sys
from numba.core.registry import CPUDispatcher
import ntncontact as ntc
from ntncontact.warmup import _scenario, exercise

def signatures():
    """Every (kernel, argument types) the package's kernels hold in this process."""
    found = set()
    for name, module in list(sys.modules.items()):
        if not name.startswith("ntncontact."):
            continue
        for attr, obj in list(vars(module).items()):
            if isinstance(obj, CPUDispatcher) and obj.py_func.__module__ == name:
                found |= {f"{name}.{attr}{tuple(map(str, sig))}" for sig in obj.signatures}
    return found

exercise(ale=True)
exercise(ale=False)
warm = signatures()

def case(edit, **sets):
    data = _scenario(True)
    data["analysis"]["t_end"] = 10 * 0.005
    edit(data)
    ntc.run(ntc.scenario_from_dict(data, overrides=sets))

def ale_ring(data):
    # the annulus is the ALE body (a closed surface chain), the obstacle Lagrangian
    data["bodies"][0] |= {"mesh_motion": "ale", "ale": {"smoothing_layers": 1}}
    del data["bodies"][1]["mesh_motion"], data["bodies"][1]["ale"]

same = lambda data: None
case(ale_ring)
case(same, **{"bodies.1.ale.interior": "displacement"})
case(same, **{"bodies.1.ale.interior": "position", "bodies.1.ale.smoothing": "angle"})
case(same, **{"analysis.mass": "lumped", "contact.0.method": "lagrange"})
case(same, **{"contact.0.friction": 0.3, "contact.0.penalty_tangential": 1000.0,
              "bodies.1.ale.remap": "linear"})
print(json.dumps(sorted(signatures() - warm)))
'''


def test_common_configurations_use_the_kernels_the_warmup_compiled():
    done = subprocess.run([sys.executable, "-c", textwrap.dedent(CODE)], capture_output=True,
                          text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    new = json.loads(done.stdout.strip().splitlines()[-1])
    assert new == [], "kernels compiled for argument types the warm-up does not run:\n" + \
        "\n".join(new)

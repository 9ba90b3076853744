import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))

import pytest  # noqa: E402


@pytest.fixture(params=["numpy", "numba"])
def both_contact_kernels(request, monkeypatch):
    """Run a test with the NumPy reference and with the compiled contact kernel
    (``pytestmark = pytest.mark.usefixtures("both_contact_kernels")`` in a module)."""
    from ntncontact.contact import evaluate

    if request.param == "numba":
        pytest.importorskip("numba")
    monkeypatch.setattr(evaluate, "KERNEL", request.param)
    return request.param

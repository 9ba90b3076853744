import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))


def pytest_collection_modifyitems(config, items):
    """Files that hold a slow test first, the rest after, each group in file order.

    ``make test`` gives each pytest-xdist worker whole files (``--dist loadfile``, with
    ``--no-loadscope-reorder`` so that this order is the order the files are handed out). By
    default xdist hands out the files with the most tests first, which put the longest file
    (tests/test_ale_both_refined.py: one test, 6-15 min) near the end: the other worker then
    waited for it (session 23: 22.8 min of wall for ~35 worker-minutes). Longest first, the
    other worker runs the rest beside it."""
    slow_files = {item.path for item in items if item.get_closest_marker("slow")}
    items.sort(key=lambda item: item.path not in slow_files)  # a stable sort

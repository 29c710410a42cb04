import sys
from pathlib import Path

# tests/synthetic.py is a helper module shared by several test files
sys.path.insert(0, str(Path(__file__).parent))


def pytest_collection_modifyitems(config, items) -> None:
    """Flights first: the end-to-end tests run in real time (tens of seconds each), the rest in
    milliseconds. With ``pytest -n 2`` the workers take tests in this order, so the quick ones
    fill the gaps at the end instead of one worker finishing a long flight alone."""
    items.sort(key=lambda item: item.get_closest_marker("e2e") is None)

import sys
from pathlib import Path

# tests/synthetic.py is a helper module shared by several test files
sys.path.insert(0, str(Path(__file__).parent))


def pytest_collection_modifyitems(config, items) -> None:
    """Flights first: the end-to-end tests run in real time (tens of seconds each), the rest in
    milliseconds. ``make test`` runs ``pytest -n 2 --dist worksteal``: the workers start on
    halves of this order and an idle one steals from the other's queue, so the flights end up
    shared and the quick tests fill the end instead of one worker finishing a flight alone."""
    items.sort(key=lambda item: item.get_closest_marker("e2e") is None)

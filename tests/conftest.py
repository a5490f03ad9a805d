"""The suite's two tiers.

The default run (``pytest -q -n auto``, the README's command) deselects the tests marked
``slow`` (pyproject's ``addopts``): robot-scale models, Dask clusters, sanitizer builds,
benchmark smokes and long tight-tolerance runs. ``pytest -q -n auto -m "slow and not
exhaustive"`` runs them; CI runs both. The slow tests also marked ``exhaustive`` (the largest
models of a full matrix, hours of CPU) are run by hand: ``pytest -q -n auto -m exhaustive``.
Every test has a time limit (pytest-timeout), generous enough for a loaded machine: pyproject's
``timeout`` (600 s) for a fast test, :data:`SLOW_TIMEOUT` for a slow one; a test that needs more
says so with ``pytest.mark.timeout``. A test moved to the slow tier names at its mark the fast
test that takes the same code path.
"""
import pytest

SLOW = ("slow: robot-scale models, Dask clusters, sanitizer builds, benchmark smokes, long "
        "tight-tolerance runs; deselected by default, run with `pytest -m slow`")


EXHAUSTIVE = ("exhaustive: slow tests too long for CI (hours of CPU in all: the largest models of a "
              "full matrix); run by hand with `pytest -q -n auto -m exhaustive`")


#: Seconds a slow test may take unless it says otherwise (``pytest.mark.timeout``).
SLOW_TIMEOUT = 900


def pytest_configure(config):
    config.addinivalue_line("markers", SLOW)
    config.addinivalue_line("markers", EXHAUSTIVE)


def pytest_collection_modifyitems(items):
    for item in items:
        if item.get_closest_marker("slow") is not None and item.get_closest_marker("timeout") is None:
            item.add_marker(pytest.mark.timeout(SLOW_TIMEOUT))


def pytest_report_header(config):
    return f"tier: -m {config.option.markexpr!r}" if config.option.markexpr else "tier: every test"


@pytest.hookimpl(trylast=True)
def pytest_terminal_summary(terminalreporter):
    deselected = terminalreporter.stats.get("deselected", [])
    slow = sum(1 for item in deselected if item.get_closest_marker("slow") is not None)
    if slow:
        terminalreporter.write_line(f"{slow} slow tests deselected: run them with "
                                    "`pytest -q -n auto -m 'slow and not exhaustive'` (and `-m exhaustive` for the longest)")

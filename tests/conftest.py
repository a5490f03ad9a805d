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

Compile flags: a run that selects no slow test (the fast tier, or some of its files) compiles
its models' packages with :data:`QUICK_CFLAGS` (``$NCGEN_CFLAGS`` for the session, unless the
environment sets it): most of the fast tier's time is gcc compiling small models' packages, and
a test's run of them is short.  ncgen's model-independent libraries (element and tree tables)
keep their own flags (``$NCGEN_CFLAGS`` does not apply to them).  No check depends on the
optimisation level: neither level reorders floating-point arithmetic (no ``-ffast-math``; on
x86-64 no fused multiply-adds without ``-mfma``), so results differ at most at round-off (a
library call such as ``pow(x, 2)`` folded into ``x*x``), below every tolerance.  The
default flags keep their own tests (``test_codegen_build.py``, which unsets ``$NCGEN_CFLAGS``)
and the -O2 builds theirs, with the flags by name (``test_reroll.py``'s looped package,
``test_reliability_optimized_warnings.py``).
In a run that includes slow tests, a module whose time is mostly gcc compiling its scenes
(contact scenes: the unrolled Delassus and KKT solves) sets ``QUICK_COMPILE = True`` to get
:data:`QUICK_CFLAGS` still, and one such test elsewhere takes the fixture ``quick_cflags``.
"""
import os

import pytest

SLOW = ("slow: robot-scale models, Dask clusters, sanitizer builds, benchmark smokes, long "
        "tight-tolerance runs; deselected by default, run with `pytest -m slow`")


EXHAUSTIVE = ("exhaustive: slow tests too long for CI (hours of CPU in all: the largest models of a "
              "full matrix); run by hand with `pytest -q -n auto -m exhaustive`")


#: Seconds a slow test may take unless it says otherwise (``pytest.mark.timeout``).
SLOW_TIMEOUT = 900

#: Flags of a fast run's compiles (module docstring): a box scene's package (6 boxes, 48 corner
#: contacts) takes 8 s of gcc CPU at -O0 against 32 s at -O2, and its 1.5 s run 0.9 s against
#: 0.3 s; the contact step Jacobians' file 29 s of CPU against 66 s.
QUICK_CFLAGS = "-O0"


def pytest_configure(config):
    config.addinivalue_line("markers", SLOW)
    config.addinivalue_line("markers", EXHAUSTIVE)


def pytest_collection_finish(session):
    """``$NCGEN_CFLAGS`` = :data:`QUICK_CFLAGS` for this process (and the processes its tests
    start) if no selected test is slow and the environment does not set it (module docstring)."""
    if "NCGEN_CFLAGS" not in os.environ and session.items and \
            not any(item.get_closest_marker("slow") is not None for item in session.items):
        os.environ["NCGEN_CFLAGS"] = QUICK_CFLAGS


@pytest.fixture(autouse=True, scope="module")
def quick_compile(request):
    """``$NCGEN_CFLAGS`` = :data:`QUICK_CFLAGS` for a module with ``QUICK_COMPILE = True``
    (module docstring), set before its module-scoped fixtures build their scenes."""
    if not getattr(request.module, "QUICK_COMPILE", False) or "NCGEN_CFLAGS" in os.environ:
        yield
        return
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("NCGEN_CFLAGS", QUICK_CFLAGS)
        yield


@pytest.fixture
def quick_cflags(monkeypatch):
    """:func:`quick_compile` for one test (in a module that also runs table-driven steppers)."""
    if "NCGEN_CFLAGS" not in os.environ:
        monkeypatch.setenv("NCGEN_CFLAGS", QUICK_CFLAGS)


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

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
a test's run of them is short.  ncgen's model-independent libraries (element, contact and tree
tables) take ``$NCGEN_CFLAGS`` too, keyed by it in the compile cache.  No check depends on the
optimisation level: neither level reorders floating-point arithmetic (no ``-ffast-math``; on
x86-64 no fused multiply-adds without ``-mfma``), so results differ at most at round-off (a
library call such as ``pow(x, 2)`` folded into ``x*x``), below every tolerance.  The
default flags keep their own tests (``test_codegen_build.py``, which unsets ``$NCGEN_CFLAGS``)
and the -O2 builds theirs, with the flags by name (``test_reroll.py``'s looped package,
``test_reliability_optimized_warnings.py``).
In a run that includes slow tests, a module whose time is mostly gcc compiling its scenes
(contact scenes: the unrolled Delassus and KKT solves) sets ``QUICK_COMPILE = True`` to get
:data:`QUICK_CFLAGS` still, and one such test elsewhere takes the fixture ``quick_cflags``.

The fast tier's budget: ≤ 5 minutes on 2 cores with an empty compile cache, ≈ 600 CPU-seconds
for its ≈ 2 500 tests.  A fast test should take at most :data:`FAST_TEST_BUDGET` CPU-seconds
(its process and the compilers it waited for; setup and teardown included, on an empty cache);
a heavier one goes to the slow tier with a fast twin.  Every run measures each test's CPU time
and ends with the fast tests over the budget and the CPU-seconds of each tier
(:func:`pytest_terminal_summary`); the first users of the element and tree libraries carry their
one compile (≈ 15 and 25 CPU-s, once per compile cache).
"""
import os
import resource

import pytest

SLOW = ("slow: robot-scale models, Dask clusters, sanitizer builds, benchmark smokes, long "
        "tight-tolerance runs; deselected by default, run with `pytest -m slow`")


EXHAUSTIVE = ("exhaustive: slow tests too long for CI (hours of CPU in all: the largest models of a "
              "full matrix); run by hand with `pytest -q -n auto -m exhaustive`")


#: Seconds a slow test may take unless it says otherwise (``pytest.mark.timeout``).
SLOW_TIMEOUT = 900

#: CPU-seconds a fast test may take (module docstring).
FAST_TEST_BUDGET = 5.0

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


def cpu_seconds() -> float:
    """CPU time of this process (all its threads) and of the child processes it has waited for."""
    own, children = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item):
    item.cpu_start = cpu_seconds()
    yield


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item, call):
    """The test's CPU-seconds (setup to teardown) on its teardown report (workers send it along)."""
    outcome = yield
    if call.when == "teardown" and hasattr(item, "cpu_start"):
        outcome.get_result().user_properties.append(("cpu_seconds", cpu_seconds() - item.cpu_start))


def pytest_runtest_logreport(report):
    if report.when == "teardown":
        cpu = dict(report.user_properties).get("cpu_seconds")
        if cpu is not None:
            CPU_OF_TESTS["slow" if "slow" in report.keywords else "fast"].append((cpu, report.nodeid))


#: ``{tier: [(CPU-seconds, node id), ...]}`` of this run's tests (in the controller with xdist).
CPU_OF_TESTS: dict[str, list[tuple[float, str]]] = {"fast": [], "slow": []}


@pytest.hookimpl(trylast=True)
def pytest_terminal_summary(terminalreporter):
    for tier, tests in CPU_OF_TESTS.items():
        if tests:
            terminalreporter.write_line(f"{tier} tests: {len(tests)}, {sum(c for c, _ in tests):.0f} CPU-s")
    over = sorted(CPU_OF_TESTS["fast"], reverse=True)
    over = [(c, n) for c, n in over if c > FAST_TEST_BUDGET]
    if over:
        terminalreporter.write_line(f"{len(over)} fast tests over the budget of {FAST_TEST_BUDGET:g} CPU-s "
                                    "(tests/conftest.py; the first users of the element and tree libraries "
                                    "carry their compile):")
        for cpu, nodeid in over:
            terminalreporter.write_line(f"  {cpu:7.1f} CPU-s  {nodeid}")
    deselected = terminalreporter.stats.get("deselected", [])
    slow = sum(1 for item in deselected if item.get_closest_marker("slow") is not None)
    if slow:
        terminalreporter.write_line(f"{slow} slow tests deselected: run them with "
                                    "`pytest -q -n auto -m 'slow and not exhaustive'` (and `-m exhaustive` for the longest)")

"""The compiled steps of rolling models called from Python: the direct call's fast copy
(sized arguments, ``(t,)``) against its checked copy (a bare float sends every argument
through the validation of :meth:`ncgen.codegen.direct.DirectFunction._copy_checked`), for
the RATTLE step with velocity constraints (``method="stepper"``) and the projected DOPRI5
step (``method="rolling"``) of the precessing disc of ``tests/test_rolling_system.py``.

Interleaved rounds of ``--calls`` calls each from the same state; prints the CPU time per
call (min, median) of each way and the ratios, and the machine.

    python benchmarks/rolling_steps.py [--calls 2000] [--repeat 5]
"""
from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))
sys.path.insert(0, str(ROOT / "tests"))
import numpy as np  # noqa: E402

import ncgen as nc  # noqa: E402
from common import machine  # noqa: E402


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--calls", type=int, default=2000)
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args(argv)
    from test_rolling_system import disc_toml

    from ncgen.assembly.nonholonomic import rolling_system
    from ncgen.runtime import rolling_integrator, rolling_stepper
    from ncgen.runtime.options import SimulationOptions
    model = nc.System.from_toml(disc_toml()).build()
    system = rolling_system(model)
    o = SimulationOptions()
    rattle = rolling_stepper.compiled_step(system, o.newton_tol, o.max_newton)
    dopri = rolling_integrator.compiled_step(system, "dopri5")
    q, v, p, u, h = model.q0, model.v0, model.p0, np.zeros(0), 1e-3
    y = np.concatenate([q, v])
    cases = {"RATTLE step": (lambda: rattle(q, v, (0.0,), (h,), u, u, p), lambda: rattle(q, v, 0.0, h, u, u, p)),
             "DOPRI5 step": (lambda: dopri(y, (h,)), lambda: dopri(y, h))}
    print(machine())
    for name, ways in cases.items():
        times = ([], [])
        for _ in range(args.repeat):
            for k, call in enumerate(ways):
                start = time.process_time()
                for _ in range(args.calls):
                    call()
                times[k].append((time.process_time() - start) / args.calls * 1e6)
        (fast, checked) = times
        print(f"{name}: sized arguments {min(fast):.1f} / {statistics.median(fast):.1f} µs, a bare float "
              f"{min(checked):.1f} / {statistics.median(checked):.1f} µs (min / median CPU per call); ratios "
              f"min {min(checked) / min(fast):.2f}, median {statistics.median(checked) / statistics.median(fast):.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""The energy assertion shared by the contact tests: contacts never create energy."""
from __future__ import annotations

import numpy as np

#: The classes of work that are the contacts' (ncgen.runtime.energy_balance.PARTS).
CONTACT_CLASSES = ("contacts", "friction", "push_out")


def created_by_contacts(traj) -> np.ndarray:
    """``E − E0`` less the work of every class but the contacts' (inputs, drives, dampers),
    at every output time (J): what the contacts did to the energy.  A conservative run
    (elastic frictionless contacts) has no work report: ``E − E0``."""
    E = np.asarray(traj.energy, float)
    works = traj.info.get("energy", {}).get("works")
    if not works:
        return E - E[0]
    others = np.asarray(works["total"], float) - sum(np.asarray(works[k], float) for k in CONTACT_CLASSES
                                                       if k in works)
    return E - E[0] - others


def assert_no_energy_created(traj, tol: float) -> None:
    """Contacts never create energy: ``E − E0 − W_inputs − W_drives − W_dampers ≤ tol`` (J) at
    every output time, and the contacts' own work (normal, friction and push-out together,
    where the run reports it) is not a gain beyond ``tol`` either."""
    gain = created_by_contacts(traj)
    worst = int(np.argmax(gain))
    assert gain[worst] <= tol, f"contacts created {gain[worst]:.3g} J by t = {traj.t[worst]:.6g} s (tol {tol:.3g})"
    works = traj.info.get("energy", {}).get("works")
    if works:
        own = sum(np.asarray(works[k], float) for k in CONTACT_CLASSES if k in works)
        assert np.max(own) <= tol, f"the contacts' work rose to {np.max(own):.3g} J (tol {tol:.3g})"

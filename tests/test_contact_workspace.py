"""A nonsmooth contact stepper too large for the machine is refused before the C runs, naming
the model and the sizes.  The workspace allocated before a run grows linearly with the impulse
components nd (the Delassus blocks are sized by the active rows during the run): a 200-sphere
all-pairs scene, nd = 60 300, needs 15 MB (before: 81 GiB of dense blocks, 3 nd² doubles)."""
from types import SimpleNamespace

import pytest

from ncgen.errors import NcgenError
from ncgen.runtime import stepper
from ncgen.runtime.stepper import check_contact_workspace


def test_a_contact_stepper_larger_than_memory_is_refused_by_name(monkeypatch):
    monkeypatch.setattr(stepper, "physical_memory", lambda: 24 << 30)       # a 24 GiB machine
    model = SimpleNamespace(name="pile")
    with pytest.raises(NcgenError, match=r"model 'pile'.*95\.4 GiB.*nd = 400,000,000.*fewer contact elements"):
        check_contact_workspace(model, 400_000_000)
    check_contact_workspace(model, 60_300)           # 200 spheres, all pairs: 15 MB, accepted
    check_contact_workspace(model, 3 * 250)          # the 20-sphere heap's size
    check_contact_workspace(model, 0)                # no contacts
    assert 1 << 30 < stepper.physical_memory() < 1 << 50

"""A nonsmooth contact stepper too large for the machine is refused before the C runs, naming
the model and the sizes (a 200-sphere all-pairs scene, nd = 60 300, needs 81 GiB of dense
contact blocks: the C's allocation failed with a bare status, and before the size's int
overflow was fixed it segfaulted)."""
from types import SimpleNamespace

import pytest

from ncgen.errors import NcgenError
from ncgen.runtime import stepper
from ncgen.runtime.stepper import check_contact_workspace


def test_a_contact_stepper_larger_than_memory_is_refused_by_name(monkeypatch):
    monkeypatch.setattr(stepper, "physical_memory", lambda: 24 << 30)       # a 24 GiB machine
    model = SimpleNamespace(name="pile200")
    with pytest.raises(NcgenError, match=r"model 'pile200'.*81\.3 GiB.*nd = 60,300.*fewer contact elements"):
        check_contact_workspace(model, 60_300)
    check_contact_workspace(model, 3 * 250)          # the 20-sphere heap's size: 13 MB, accepted
    check_contact_workspace(model, 0)                # no contacts
    assert 1 << 30 < stepper.physical_memory() < 1 << 50

"""A section of a model package: functions, their documentation, metadata and extra C
sources that :func:`ncgen.codegen.model_package.generate` merges in order."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Mapping, Sequence

import casadi as ca

from ncgen.codegen.package import ExtraSource


@dataclass(frozen=True)
class Section:
    """One part of a model package: CasADi ``functions`` and their ``docs``
    (:class:`~ncgen.codegen.doc.FunctionDoc` data by function name), the names of those
    generated with a Jacobian, ``metadata`` with its one-line ``metadata_doc``, and
    ``extra_sources`` (templates rendered next to the kernels)."""

    functions: Sequence[ca.Function] = ()
    docs: Mapping[str, Mapping] = field(default_factory=dict)
    jacobians: Sequence[str] = ()
    metadata: Mapping[str, object] = field(default_factory=dict)
    metadata_doc: Mapping[str, str] = field(default_factory=dict)
    extra_sources: Sequence[ExtraSource] = ()

"""Tensegrity design files (TOML): a shape, its supports and loads, and what to ask of it.

```toml
nodes = [[0.3, 0.0, 0.0], ...]        # m, n × 2 or n × 3
struts = [[0, 3], ...]                # node indices
cables = [[0, 1], ...]
supports = { 0 = "xyz", 2 = "z" }     # node = held axes (optional)
loads = [{ node = 3, force = [0.0, 0.0, -1.0] }]      # N (optional)
clusters = [[0, 1, 2]]                # clustered cables (optional), with
friction = [0.0]                      # one coefficient per cluster (optional)
bodies = [[0, 1, 2]]                  # rigid bodies through these nodes (optional)

[prestress]                           # optional
objective = "least_norm"              # or "stiffness", "max_cable"
cable_min = 10.0                      # N
cable_max = 50.0                      # N (optional)
strut_max = 100.0                     # N of compression (optional)
stiffness = 2000.0                    # N/m: also report the cables' rest lengths (optional)
```

:func:`read_design` checks it (errors name the key); :func:`run_design` prints the
self-stress analysis and the member forces (:func:`~ncgen.analysis.inverse_statics.inverse_statics`
or :func:`~ncgen.analysis.prestress.optimize_prestress`).  ``ncgen tensegrity FILE`` runs it.
"""
from __future__ import annotations

import tomllib
from pathlib import Path

import numpy as np

from ncgen.errors import NcgenError

TOP_KEYS = ("nodes", "struts", "cables", "supports", "loads", "clusters", "friction", "bodies", "prestress")
PRESTRESS_KEYS = ("objective", "cable_min", "cable_max", "strut_max", "stiffness")
OBJECTIVES = ("least_norm", "stiffness", "max_cable")


def read_design(path) -> dict:
    """The design in ``path`` as keyword arguments: ``nodes``, ``struts``, ``cables``,
    ``supports``, ``loads`` (n × dim), ``clusters``, ``friction``, ``bodies`` and ``prestress`` (a dict
    with the keys of ``[prestress]``, ``objective`` defaulting to ``"least_norm"``)."""
    path = Path(path)
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except OSError as e:
        raise NcgenError(f"{path}: cannot read the tensegrity file ({e.strerror})") from None
    except tomllib.TOMLDecodeError as e:
        raise NcgenError(f"{path}: not valid TOML: {e}") from None
    where = str(path)
    unknown = sorted(set(data) - set(TOP_KEYS))
    if unknown:
        raise NcgenError(f"{where}: unknown key(s) {unknown}; expected {', '.join(TOP_KEYS)}")
    for key in ("nodes", "struts", "cables"):
        if key not in data:
            raise NcgenError(f"{where}: {key}: missing (expected a list of {'coordinates' if key == 'nodes' else 'node pairs'})")
    nodes = _array(data["nodes"], f"{where}: nodes", "a list of node coordinates (m)")
    if nodes.ndim != 2 or nodes.shape[1] not in (2, 3):
        raise NcgenError(f"{where}: nodes: expected n points of 2 or 3 coordinates, got shape {nodes.shape}")
    n, d = nodes.shape
    supports = {}
    for key, axes in data.get("supports", {}).items():
        if not key.isdigit():
            raise NcgenError(f"{where}: supports.{key}: expected a node index as the key")
        supports[int(key)] = axes
    loads = np.zeros((n, d))
    for i, item in enumerate(data.get("loads", [])):
        at = f"{where}: loads[{i}]"
        if not isinstance(item, dict) or set(item) != {"node", "force"}:
            raise NcgenError(f"{at}: expected {{ node = INDEX, force = [...] }}, got {item!r}")
        node = item["node"]
        if not isinstance(node, int) or not 0 <= node < n:
            raise NcgenError(f"{at}.node: expected a node index in 0..{n - 1}, got {node!r}")
        force = _array(item["force"], f"{at}.force", f"{d} force components (N)")
        if force.shape != (d,):
            raise NcgenError(f"{at}.force: expected {d} force components (N), got {force.size}")
        loads[node] += force
    prestress = dict(data.get("prestress", {}))
    unknown = sorted(set(prestress) - set(PRESTRESS_KEYS))
    if unknown:
        raise NcgenError(f"{where}: prestress: unknown key(s) {unknown}; expected {', '.join(PRESTRESS_KEYS)}")
    prestress.setdefault("objective", "least_norm")
    if prestress["objective"] not in OBJECTIVES:
        raise NcgenError(f"{where}: prestress.objective: expected one of {', '.join(map(repr, OBJECTIVES))}, "
                         f"got {prestress['objective']!r}")
    for key in PRESTRESS_KEYS[1:]:
        if key in prestress and (isinstance(prestress[key], bool) or not isinstance(prestress[key], (int, float))):
            raise NcgenError(f"{where}: prestress.{key}: expected a number, got {prestress[key]!r}")
    return dict(nodes=nodes, struts=data["struts"], cables=data["cables"], supports=supports, loads=loads,
                clusters=data.get("clusters"), friction=data.get("friction"), bodies=data.get("bodies"),
                prestress=prestress)


def _array(x, what: str, expected: str) -> np.ndarray:
    try:
        a = np.array(x, float)
    except (TypeError, ValueError):
        raise NcgenError(f"{what}: expected {expected}, got {x!r}") from None
    if not np.all(np.isfinite(a)):
        raise NcgenError(f"{what}: expected finite numbers, got {x!r}")
    return a


def run_design(design: dict) -> tuple[str, object]:
    """``(report, result)``: the self-stress analysis and the member forces of a design read
    by :func:`read_design` (the result is an ``InverseStatics`` or a ``PrestressDesign``)."""
    from ncgen.analysis.inverse_statics import inverse_statics
    from ncgen.analysis.prestress import optimize_prestress

    ps = dict(design["prestress"])
    objective, stiffness = ps.pop("objective"), ps.pop("stiffness", None)
    shape = (design["nodes"], design["struts"], design["cables"])
    kw = dict(loads=design["loads"], supports=design["supports"], clusters=design["clusters"],
              friction=design["friction"], bodies=design.get("bodies"), **ps)
    if objective == "least_norm":
        res = inverse_statics(*shape, **kw)
    else:
        res = optimize_prestress(*shape, objective=objective, **kw)
    an = res.analysis
    text = an.table() + "\n" + res.table()
    if objective != "least_norm":
        text += (f"objective {objective}: smallest mechanism stiffness {res.min_stiffness:.6g} N/m, largest cable "
                 f"{res.max_cable:.6g} N ({res.iterations} IPOPT iterations)\n")
    stability, ev = an.prestress_stability(res.forces)
    text += f"prestress stability: {stability}" + (f" (mechanism stiffness >= {ev.min():.6g} N/m)\n" if ev.size else "\n")
    if stiffness is not None:
        l0 = res.rest_lengths(stiffness)[:len(res.framework.cables)]
        text += f"cable rest lengths (m) at {stiffness:g} N/m: " + " ".join(f"{x:.6g}" for x in l0) + "\n"
    return text, res

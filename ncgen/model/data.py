"""A model's run-time data, in one place (Pinocchio's ``Data`` beside its ``Model``).

A :class:`~ncgen.model.model.Model` is constant.  Everything a process computes for it
beyond the model itself — the compiled libraries, the kernels loaded from them, functions
built on demand, the lazily built ``share=False`` form — lives in its :class:`ModelData`,
``model.data`` (:func:`model_data`).  The data is kept on the model (``model._data``, made
with it), so it goes with the model: the cycles model → data → door → model are Python's
cyclic GC's to collect, and no module-level dictionary holds a model or anything holding one
(compiled libraries shared between models stay in their caches, which hold no model).  It is
never part of the model's pickled or stored state, and is filled slot by slot on first use
by the module that owns the slot.

A model can have these compiled libraries (docs/architecture.md):

* the **model package** (``libraries``): every function of ``model.functions`` and the
  compiled stepper, one library per set of compiler flags; IDAS's ``dae`` and the stepper
  are loaded from it;
* the **forward-dynamics kernel** (``forward_dynamics_kernels``): ``kkt_function`` (or its
  joint-space form) alone;
* the **tree kernel** (``tree_kernels``): the joint-space forward dynamics of a tree alone;
* the **joint-space loops** (``joint_loops``): the joint-space ODE and its integration loop;
* the **tree algorithms** (``algorithm_kernels``): RNEA, CRBA, ABA and their derivatives,
  one library each.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable

from ncgen.errors import ModelError


@dataclass(eq=False)
class ModelData:
    """The run-time data of one model; each slot names the module that fills it."""

    #: ``{cflags key: CompiledModel}``: the model package compiled
    #: (:func:`ncgen.runtime.library.compiled_model`).
    libraries: dict = field(default_factory=dict)
    #: IDAS's ``dae`` loaded from the model package, or None (:func:`ncgen.runtime.dae.load_dae`).
    dae: object = None
    #: ``{cflags key: CompiledStepper}``: the stepper's loops loaded from the model package
    #: (:func:`ncgen.runtime.stepper_library.load_stepper`).
    steppers: dict = field(default_factory=dict)
    #: Whether the forces are conservative and the constraints scleronomic, or None
    #: (:func:`ncgen.runtime.stepper_checks.is_conservative`).
    conservative: bool | None = None
    #: The same with the inputs at zero (``is_conservative(model, inputs=False)``).
    conservative_idle: bool | None = None
    #: ``{joint_space: DirectFunction}``: the compiled forward dynamics
    #: (:func:`ncgen.runtime.dynamics_at_state.forward_dynamics_kernel`).
    forward_dynamics_kernels: dict = field(default_factory=dict)
    #: ``nc.forward_dynamics(..., backend="compiled")``'s door (False: none)
    #: (:func:`ncgen.runtime.dynamics_at_state.forward_dynamics_door`).
    forward_dynamics_door: object = None
    #: ``{(method, cflags): JointDynamicsKernel or the ModelError of a non-tree}``
    #: (:func:`ncgen.runtime.tree_kernel.joint_forward_dynamics_kernel`).
    tree_kernels: dict = field(default_factory=dict)
    #: ``nc.joint_forward_dynamics``' own copy of the default tree kernel (False: none).
    tree_kernel: object = None
    #: ``{(name, cflags): AlgorithmKernel or the ModelError of a non-tree}``: RNEA, CRBA, ABA
    #: and the derivatives, each its own library (:func:`ncgen.runtime.tree_algorithm_kernels.algorithm_kernel`).
    algorithm_kernels: dict = field(default_factory=dict)
    #: ``(TreeTables or None, UnsupportedTree or None)``: the model's tree tables
    #: (:func:`ncgen.codegen.tree_tables.tree_tables`).
    tree_tables: tuple | None = None
    #: ``{(name, library key): TableAlgorithm}``, ``{(None, library key): BoundTree}``: the tree
    #: library's algorithms bound to the model's tables, per the flags of the library's units
    #: (:func:`ncgen.runtime.tree_library.table_algorithm`, ``library_key``).
    table_algorithms: dict = field(default_factory=dict)
    #: ``{(name, kernels): Door}``: the bound doors of the tree algorithms, found in one lookup
    #: a call, ``model._data.doors.get((name, kernels))`` (:func:`ncgen.runtime.tree_algorithm_kernels.door`).
    doors: dict = field(default_factory=dict)
    #: ``(indices,)``: the independent joint rates when the compiled algorithms take the model,
    #: indices None when not (:func:`ncgen.runtime.tree_algorithm_kernels.rnea_applies`).
    algorithm_rates: tuple | None = None
    #: ``{joints: bool}``: whether the compiled RNEA gives ``nc.inverse_dynamics(...,
    #: joints=joints)`` (:func:`ncgen.runtime.dynamics_at_state._rnea_gives`).
    rnea_efforts: dict = field(default_factory=dict)
    #: ``(f,)``: the joint-space tree map ``(q_j, v_j) -> (q, v)``, f None for a model that is
    #: not a tree (``JointSpace._tree`` in :mod:`ncgen.assembly.joint_space`).
    joint_tree_function: tuple | None = None
    #: The joint positions at ``model.q0``, by joint (``JointSpace._propagate``).
    joint_positions0: dict | None = None
    #: The rerolled primitives of a large model (:func:`ncgen.codegen.looped.rerolled_primitives`).
    rerolled: dict | None = None
    #: ``{name: casadi.Function}``: analysis functions built on demand
    #: (:func:`ncgen.analysis.stability.cached`: statics, linearisation).
    functions: dict = field(default_factory=dict)
    #: ``(reason,)``: why the model has no joint-space transcription (reason None: it has one)
    #: (:func:`ncgen.optim.joint_radau.joint_space_reason`).
    joint_space_reason: tuple | None = None
    #: ``{(controller id, joint_dynamics, cflags): (controller, JointLoop)}``: the compiled
    #: joint-space simulation loops (:func:`ncgen.runtime.joint_simulation.joint_loop`).
    joint_loops: dict = field(default_factory=dict)
    #: ``{key: PreparedRun}``: what a joint-space run derives from its options, output count,
    #: controller and compiler but not from its start (the loop, its kernel choice, the info
    #: template; :func:`ncgen.runtime.joint_simulation.prepared_run`), up to
    #: :data:`~ncgen.runtime.joint_simulation.KEPT_RUNS`.
    prepared_runs: dict = field(default_factory=dict)
    #: ``{key: Plan}``: what ``simulate`` derives from its arguments in the call without inputs,
    #: parameters or ``t0`` (:func:`ncgen.runtime.simulation.simulate`), up to
    #: :data:`~ncgen.runtime.simulation.KEPT_PLANS`.
    simulate_plans: dict = field(default_factory=dict)
    #: The lists of names of the model's trajectories (:func:`ncgen.runtime.trajectory.output_names`).
    output_names: dict | None = None
    #: The model's constraints and accelerations with its nonholonomic elements
    #: (:func:`ncgen.assembly.nonholonomic.rolling_system`), or None.
    rolling_system: object = None
    #: ``(kinds,)``: the joint kinds of the tree tables' loop (None: the tables do not cover the
    #: model), and ``(reason,)``: why the model's own loop was found compiled earlier (None: it was
    #: not), looked up once per process (:func:`ncgen.runtime.joint_simulation.choose_kernels`).
    table_kinds: tuple | None = None
    flat_loop_stored: tuple | None = None
    #: ``{(t, q, v, p) as bytes: (q_j, v_j)}``: starts that passed the joint run's start check,
    #: up to :data:`ncgen.assembly.joint_space.KEPT_STARTS` (``JointSpace._checked_state``).
    checked_starts: dict = field(default_factory=dict)
    #: ``(reason,)``: why ``simulate`` cannot run the model in joint space (reason None: it can)
    #: (:func:`ncgen.runtime.joint_simulation.joint_space_applies`).
    joint_simulation_reason: tuple | None = None
    #: The model built with ``share=False`` and the map ``(S, c)`` to its coordinates
    #: (:class:`ncgen.assembly.unshared.UnsharedForm`).
    unshared_model: object = None
    unshared_map: tuple | None = None
    #: :attr:`Model.content_hash <ncgen.model.model.Model.content_hash>`, and the system's
    #: description a pickle sends (``System.description()``), computed on first use.
    content_hash: str | None = None
    description: tuple | None = None
    #: ``{library: loops}``: the stepper's loops bound for addresses, and the compiled
    #: ``accel`` of the initial multipliers (:mod:`ncgen.runtime.batch`).
    batch_loops: dict = field(default_factory=dict)
    batch_accel: object = None
    #: ``{id(force): (force, B or None)}``: the constant input map ``Q = B u`` of each force,
    #: checked symbolically once (:func:`ncgen.codegen.stepper_tables.input_force_map`).
    input_force_maps: dict = field(default_factory=dict)
    #: ``{id(joint): (joint, ActuatorElement or None)}``: each actuated joint's table element,
    #: checked symbolically once (:func:`ncgen.codegen.stepper_tables.actuator_element`).
    actuator_elements: dict = field(default_factory=dict)
    #: ``{name: BufferedFunction}``: functions called through preallocated buffers
    #: (:func:`ncgen.model.buffered_call.buffered`).
    buffered: dict = field(default_factory=dict)
    #: The model's key in the store of built models (:mod:`ncgen.codegen.model_cache`) when it
    #: was read from or written to it; functions derived from it are stored under it too.
    store_key: str | None = None


def model_data(model) -> ModelData:
    """The :class:`ModelData` of ``model`` (``model._data``, made with the model); anything
    but a model is refused, naming what it is."""
    try:
        return model._data
    except AttributeError:
        raise ModelError(f"expected an ncgen model (nc.System(...).build(), or System.from_urdf(...).build()), "
                         f"got {type(model).__name__} {model!r:.60}") from None


def cached(slot: dict, key, build: Callable[[], Any]):
    """``slot[key]``, built by ``build()`` on first use; a :class:`ModelError` raised by
    ``build`` is kept in the slot and raised again on every later call (a model that cannot
    have a kernel is told so at once, without rebuilding)."""
    hit = slot.get(key)
    if isinstance(hit, ModelError):
        raise hit
    if hit is None:
        try:
            hit = slot[key] = build()
        except ModelError as e:
            slot[key] = e
            raise
    return hit

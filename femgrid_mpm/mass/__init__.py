"""Grid mass: lumped (paper Eqs. 15-16), HRZ, consistent (Eqs. 10, 17, 19, 20), iterated and per body.

Every model implements :class:`~.protocol.MassModel`: ``assemble`` once per
step, then ``grid_velocity`` (Eq. 17) and ``solve`` for the nodal
accelerations (Eq. 10).  Nodes that no point touches are *inactive*: their
solution is zero.  What a model needs from the particle-to-grid pass it
declares in ``assembly`` (:class:`~.protocol.Assembly`).

=====================  ==========================================================
``protocol.py``        the interface, what P2G must produce, the iteration's inertia
``diagonal.py``        :class:`LumpedMass` (row sums, the mass threshold), :class:`HrzMass`
``per_body.py``        :class:`FieldLumpedMass`: one lumped field per body (frictional contact)
``consistent.py``      :class:`ConsistentMass`: weak nodes, exclusion, the singular fallback
``system.py``          one linear system of it (components, exclusions, factors, blend)
``direct.py``          SuperLU and its pivots, the test of singularity
``reused.py``          SuperLU factors kept over steps as CG's preconditioner ("auto", small grids)
``singular.py``        CG's test of singularity near the edges (signed bases)
``cg.py``              preconditioned CG, compiled, and its first guess
``preconditioners.py`` the splines' tensor Gram preconditioner and its boundary layer
``sparse.py``          compiled products of the matrix with nodal vectors
``exclusion.py``       weak-node lumping and exclusion, in place on the fixed pattern
``scale.py``           :class:`CellMasses`: a full cell of the material at each node, the scale of "empty"
``constraint.py``      mirrored ghost nodes: ``v = T w`` and the mass ``T.T M T`` (:class:`ConstrainedMass`)
``weak_rows.py``       the rows that set the consistent mass's critical step; the mixed mass
``iterated.py``        :class:`IteratedMass`: the consistent mass solved by k Jacobi corrections
=====================  ==========================================================
"""

from __future__ import annotations

import numpy as np

from .consistent import ConsistentMass
from .iterated import IteratedMass
from .layout import DIRECT_LIMIT
from .constraint import ConstrainedMass, NodeConstraint
from .diagonal import HrzMass, LumpedMass, positive_weights
from .per_body import FieldLumpedMass
from .preconditioners import tensor_preconditioner
from .protocol import Assembly, Inertia, MassModel, NodalSums, SingularMassError
from .scale import CellMasses
from .weak_rows import interior_ratio

__all__ = [
    "Assembly", "CellMasses", "OWN_KEYS", "reads", "ConsistentMass", "ConstrainedMass", "NodeConstraint", "DIRECT_LIMIT", "FieldLumpedMass", "HrzMass", "Inertia", "IteratedMass", "LumpedMass", "MassModel",
    "NodalSums", "SingularMassError", "build_mass_model", "positive_weights", "tensor_preconditioner",
]


def build_mass_model(solver, grid, cells: CellMasses, per_body: bool = False,
                     fixed: np.ndarray | None = None, time_step: float | None = None,
                     constraint: NodeConstraint | None = None) -> MassModel:
    """The mass model a scene's ``[solver]`` table asks for, complete.

    Parameters
    ----------
    solver : femgrid_mpm.scene.SolverSpec
    grid : femgrid_mpm.Grid
    cells : CellMasses
        A full lattice cell's mass of each body (kg) and its points: the scale for "empty".
    per_body : bool
        One lumped field per body (frictional contact).
    fixed : ndarray of bool, shape (n_nodes, 2), optional
        Degrees of freedom the supports hold at zero.
    time_step : float, optional
        The run's step (s), for CG's first guess (None: an estimate's model).
    constraint : NodeConstraint, optional
        Mirrored ghost nodes (supports with ``ghosts = "mirrored"``), the held degrees
        of freedom included: the model solves on ``v = T w`` (:mod:`.constraint`).
    """
    if constraint is not None:
        if per_body:
            raise ValueError("supports with ghosts = 'mirrored' need one shared velocity field (not frictional contact)")
        if solver.mass == "iterated":
            raise ValueError("supports.ghosts: 'mirrored' folds the ghost nodes into their images (the mass T.T M T), "
                             "which solver.mass = \"iterated\" does not implement: use ghosts = \"fixed\" with it, or "
                             "solver.mass = \"consistent\" or \"lumped\"")
        # mirrored ghost nodes are tied to interior ones: their rows are not weak once folded
        inner = _unconstrained(solver, grid, cells, time_step, solves=False, weak_ratio=0.0)
        return ConstrainedMass(inner, constraint, diagonal=not isinstance(inner, ConsistentMass))
    if per_body:
        return FieldLumpedMass(grid.n_nodes, cells)
    return _unconstrained(solver, grid, cells, time_step, fixed)


#: the solver keys that only these mass kinds read (:func:`_unconstrained`): a scene of
#: another kind runs the same whatever their value, and a sweep runs it once and leaves
#: them out of its label
OWN_KEYS = {"mass_corrections": ("iterated",),
            **{key: ("consistent",) for key in ("weak_fraction", "cg_tolerance", "linear_solver",
                                                  "consistent_fallback", "blend", "weak_ratio", "weak_mix", "mix")}}


def reads(mass: str, key: str) -> bool:
    """Whether a scene with ``solver.mass = mass`` reads ``solver.<key>`` (any key not in
    :data:`OWN_KEYS` is read by every kind)."""
    return mass in OWN_KEYS.get(key, (mass,))


def _unconstrained(solver, grid, cells: CellMasses, time_step: float | None, fixed: np.ndarray | None = None,
                   solves: bool = True, weak_ratio: float | None = None) -> MassModel:
    """The shared field's model of the scene's kind (``weak_ratio``: the scene's unless given)."""
    weak_ratio = solver.weak_ratio if weak_ratio is None else weak_ratio
    if solver.mass == "hrz":
        return HrzMass(grid.n_nodes, cells)
    if solver.mass == "lumped":
        if solver.negative_mass == "threshold":
            return LumpedMass(grid.n_nodes, cells, threshold=solver.mass_threshold,
                              node_integrals=grid.node_integrals)
        return LumpedMass(grid.n_nodes, cells)
    if solver.mass == "iterated":  # lumped mass and a fixed number of corrections towards consistent mass
        k = solver.mass_corrections  # its products from the points while they cost less (.iterated)
        return IteratedMass(grid.n_nodes, cells, corrections=k, fixed=fixed, assembled=8 * k > grid.n_local + 4)
    return ConsistentMass(
        grid.n_nodes,
        cells,
        node_integrals=grid.node_integrals,
        nonnegative=grid.nonnegative,
        weak_fraction=solver.weak_fraction,
        tolerance=solver.cg_tolerance,
        linear_solver=solver.linear_solver,
        fallback=solver.consistent_fallback,
        blend=solver.blend,
        fixed=fixed,
        preconditioner=tensor_preconditioner(grid),
        lattice=None if grid.nonnegative else grid.lattice_indices,
        layer_width=round(grid.discretization.element_width / grid.spacing),  # in lattice steps
        time_step=time_step,
        solves=solves,
        weak_ratio=weak_ratio,
        weak_mix=solver.weak_mix,
        interior=interior_ratio(grid) if weak_ratio > 0 and grid.nonnegative else 0.0,
        mix=solver.mix,
    )

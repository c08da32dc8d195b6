"""The performance paths compute what the plain ones do: the tensor preconditioner,
the fixed mass pattern, the compiled CSR product and the benchmark's scene."""

import dataclasses
import sys
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from femgrid_mpm import Grid
from femgrid_mpm.bases import BASES
from femgrid_mpm.kernels.tables import separated_tables
from femgrid_mpm.kernels.pattern import mass_pattern
from femgrid_mpm.mass.cg import _column_dots, _preconditioned_cg, _target
from femgrid_mpm.mass.preconditioners import _apply_tensor, tensor_preconditioner
from femgrid_mpm.mass.sparse import _symmetric_times_dense_dot
from femgrid_mpm.solver import Simulation

sys.path.insert(0, str(Path(__file__).parents[1] / "benchmarks"))
from step import block_scene  # noqa: E402


@pytest.mark.parametrize("basis", list(BASES))
def test_mass_pattern_is_the_structure_of_the_mass_matrix(basis):
    """Exactly the couplings of N.T N for points everywhere, and every diagonal entry."""
    grid = Grid(basis, (0.0, 0.0), (3.0, 2.0), 0.5)
    tables = separated_tables(grid)
    pattern = mass_pattern(grid, tables.tensor.connectivity if tables.tensor else tables.connectivity)
    points = grid.lower + np.random.default_rng(0).random((3000, 2)) * (grid.upper - grid.lower)
    N, _, _ = grid.shape_functions(points)
    coupled = (abs(N).T @ abs(N)).tocsr() > 0
    structure = pattern.matrix()
    structure.data[:] = 1.0
    assert (coupled != (structure > 0)).nnz == 0
    np.testing.assert_array_equal(pattern.indices[pattern.diagonal], np.arange(grid.n_nodes))


@pytest.mark.parametrize("basis", list(BASES))
def test_symmetric_product_reads_one_entry_of_each_pair(basis):
    """In every row of the pattern the entries after the diagonal, with their transposes,
    are each off-diagonal coupling exactly once; so the product from that half
    (:func:`_symmetric_times_dense_dot`) is scipy's ``A @ x`` of the assembled,
    lumped and reduced matrices, to 1e-14 of its scale, for one and two columns."""
    simulation = Simulation(block_scene(basis, "consistent", 400))
    simulation.advance()
    pattern = simulation.transfer.pattern
    rows = np.repeat(np.arange(len(pattern.indptr) - 1), np.diff(pattern.indptr))
    after = np.arange(len(pattern.indices)) > pattern.diagonal[rows]
    upper = set(zip(rows[after].tolist(), pattern.indices[after].tolist()))
    lower = set(zip(pattern.indices[after].tolist(), rows[after].tolist()))
    off_diagonal = set(zip(rows.tolist(), pattern.indices.tolist())) - {(i, i) for i in range(len(pattern.indptr) - 1)}
    assert not upper & lower and upper | lower == off_diagonal
    rng = np.random.default_rng(3)
    for matrix in (simulation.mass.matrix, simulation.mass._systems[0].matrix):
        assert matrix.upper_start is not None
        for columns in (1, 2):
            x = rng.normal(size=(matrix.shape[0], columns))
            expected = sp.csr_matrix(matrix) @ x
            np.testing.assert_allclose(matrix @ x, expected, rtol=0, atol=1e-14 * np.abs(expected).max())
            out, dot = np.empty_like(x), np.zeros(columns)
            _symmetric_times_dense_dot(matrix.indptr, matrix.indices, matrix.data, matrix.upper_start, x, out, dot)
            np.testing.assert_allclose(dot, np.einsum("ij,ij->j", x, expected), rtol=1e-13)


@pytest.mark.parametrize("basis", ["bspline3", "bspline3_open"])
def test_tensor_preconditioner_is_symmetric_positive_definite(basis):
    grid = Grid(basis, (0.0, 0.0), (3.0, 2.0), 0.5)
    preconditioner = tensor_preconditioner(grid)
    n = grid.n_nodes
    rng = np.random.default_rng(1)
    scale = rng.uniform(0.5, 2.0, n)
    excluded = rng.random(n) < 0.1
    scale[excluded] = 0.0
    identity = np.eye(n)
    P = _apply_tensor(identity, np.empty_like(identity), scale, excluded, preconditioner.factor_x, preconditioner.factor_y)
    np.testing.assert_allclose(P, P.T, rtol=0, atol=1e-12 * np.abs(P).max())
    assert np.linalg.eigvalsh(0.5 * (P + P.T)).min() > 0
    assert tensor_preconditioner(Grid("q1", (0.0, 0.0), (3.0, 2.0), 0.5)) is None


def test_preconditioned_cg_solves_the_consistent_system():
    """CG (tensor preconditioner, compiled) against SuperLU on the same matrix."""
    simulation = Simulation(block_scene("bspline3", "consistent", 400))
    simulation.mass.linear_solver = "cg"
    simulation.mass.tolerance = 1e-12
    simulation.advance()
    system = simulation.mass._systems[0]
    rhs = np.where(system.excluded[:, None], 0.0, simulation.context.force)
    solution = simulation.mass._solve(system, rhs, "check")[0]
    expected = spla.spsolve(system.matrix.tocsc(), rhs)
    np.testing.assert_allclose(solution, expected, rtol=0, atol=1e-9 * np.abs(expected).max())
    assert 0 < simulation.mass.iterations < 60 * 2 * 2  # ~25 per solve, against ~100 with Jacobi here


def test_boundary_layer_is_symmetric_positive_definite_and_cuts_iterations():
    """The layered preconditioner (exact solve on the nodes near the body's edge, the
    tensor one elsewhere: layer - tensor - layer) on a real system: symmetric and
    positive definite as an explicit matrix, and CG with it reaches SuperLU's solution
    (to 1e-9) in less than half the iterations of the tensor preconditioner alone."""
    simulation = Simulation(block_scene("bspline3", "consistent", 2500))  # a layer below LAYER_LIMIT
    mass = simulation.mass
    mass.linear_solver = "cg"
    simulation.advance()
    system = mass._systems[0]
    tensor = mass.preconditioner.scaled(system)
    layer = system.boundary_layer(mass.preconditioner.lattice_shape, mass._weak)
    kept = ~system.excluded
    assert layer is not None and 0 < layer.nodes.size < kept.sum()
    identity = np.eye(simulation.grid.n_nodes)
    P = layer.sweep(identity, tensor)
    np.testing.assert_allclose(P, P.T, rtol=0, atol=1e-10 * np.abs(P).max())
    assert np.linalg.eigvalsh(0.5 * (P + P.T)).min() > 0
    rhs = np.where(system.excluded[:, None], 0.0, simulation.context.force)
    expected = spla.spsolve(system.matrix.tocsc(), rhs)
    start = np.zeros_like(rhs)
    layered = _preconditioned_cg(system.matrix, rhs, start, system.inverse_diagonal, 1e-12, 1000, tensor, layer)
    alone = _preconditioned_cg(system.matrix, rhs, start, system.inverse_diagonal, 1e-12, 1000, tensor)
    for solution, converged, _ in (layered, alone):
        assert converged
        np.testing.assert_allclose(solution, expected, rtol=0, atol=1e-9 * np.abs(expected).max())
    assert 0 < 2 * layered[2] < alone[2]


@pytest.mark.parametrize("rollers", [False, True])
def test_compiled_layered_cg_is_the_python_loop(rollers):
    """CG with a :class:`BoundaryLayer` on the compiled matrix runs compiled; the Python loop
    (the scipy engine's, reached here through a layer that is not a ``BoundaryLayer``) makes
    the same iterates bit for bit: converged, stopped at the iteration limit, and stopped at
    ``r.z < 0`` (the layer's pivots negated: ``converged`` None), and at a tolerance whose target
    the first guess's residual meets within a rounding (where two sums of the right-hand side's
    squares in other orders would stop apart: numpy's norm of one column sums pairwise), on a
    system of both velocity components and on the two one-component systems of a block on
    rollers."""
    scene = block_scene("bspline3", "consistent", 2500)
    if rollers:
        scene = type(scene).model_validate({**scene.model_dump(), "supports": [{"where": "x <= 2", "fix": ["x"]}]})
    simulation = Simulation(scene)
    mass = simulation.mass
    mass.linear_solver = "cg"
    simulation.advance()
    assert [len(system.columns) for system in mass._systems] == ([1, 1] if rollers else [2])

    class InPython:
        def __init__(self, layer):
            self.sweep = layer.sweep

    for system in mass._systems:
        tensor = mass.preconditioner.scaled(system)
        layer = system.boundary_layer(mass.preconditioner.lattice_shape, mass._weak)
        negative = dataclasses.replace(layer, factors=dataclasses.replace(layer.factors, pivots=-layer.factors.pivots))
        rhs = np.ascontiguousarray(np.where(system.excluded[:, None], 0.0, simulation.context.force[:, system.columns]))
        guess = 0.9 * rhs * system.inverse_diagonal[:, None]
        start = np.sqrt(_column_dots(rhs - system.matrix @ guess, rhs - system.matrix @ guess))
        edge = start[0] / np.linalg.norm(rhs[:, 0])
        if rollers:  # a tolerance whose targets by numpy's pairwise sum and by the sum in order straddle it
            edge = next(rtol for rtol in edge * (1 + 1e-16 * np.arange(-64, 64))
                        if (start[0] <= rtol * np.linalg.norm(rhs[:, 0])) != (start[0] <= _target(rhs, rtol)[0]))
        outcomes = []
        for chosen, first, rtol, limit in ((layer, 0 * rhs, 1e-12, 1000), (layer, 0 * rhs, 1e-12, 3),
                                           (negative, 0 * rhs, 1e-12, 1000), (layer, guess, edge, 1000)):
            compiled_run, python_run = (
                _preconditioned_cg(system.matrix, rhs, first, system.inverse_diagonal, rtol, limit, tensor, how)
                for how in (chosen, InPython(chosen)))
            assert np.array_equal(compiled_run[0], python_run[0]) and compiled_run[1:] == python_run[1:]
            outcomes.append(compiled_run[1:])
        assert outcomes[0][0] is True and outcomes[1] == (False, 3) and outcomes[2][0] is None


def test_boundary_layer_keeps_its_layout_while_its_nodes_stay():
    """The layer's block is factored every step by the compiled ``L D L^T`` on a layout kept
    while the system's excluded and weak nodes and the layer's rows stay: the next step takes
    the same layout object, its solve is numpy's dense solve of ``M[nodes][:, nodes]`` to 1e-12
    and zero outside the layer, its rows are ``M[nodes, :]`` exactly; other weak nodes, or
    the layer's rows stored elsewhere or in another order (the same matrix without its stored
    zeros, or with two entries of a row swapped), make a new layout, whose solve is the same."""
    from femgrid_mpm.mass.preconditioners import BoundaryLayer, layout_of

    simulation = Simulation(block_scene("bspline3", "consistent", 2500))
    mass = simulation.mass
    mass.linear_solver = "cg"
    simulation.advance()
    first = mass._layer_layouts[((0, 1), False)]
    simulation.advance()
    system = mass._systems[0]
    layer = system.boundary_layer(mass.preconditioner.lattice_shape, mass._weak, mass._layer_layouts)
    assert layer.layout is first
    matrix = sp.csr_matrix((system.matrix.data, system.matrix.indices, system.matrix.indptr), shape=system.matrix.shape)
    rows = matrix[layer.nodes]
    stored = sp.csr_matrix((layer.rows_data, layer.layout.rows_indices, layer.layout.rows_indptr), shape=rows.shape)
    assert abs(rows - stored).max() == 0.0
    rhs = np.random.default_rng(1).standard_normal((matrix.shape[0], 2))
    expected = np.linalg.solve(rows[:, layer.nodes].toarray(), rhs[layer.nodes])
    solution = layer.factors.solve(rhs)
    np.testing.assert_allclose(solution[layer.nodes], expected, rtol=0, atol=1e-12 * np.abs(expected).max())
    assert not np.delete(solution, layer.nodes, axis=0).any()
    weak = mass._weak.copy()
    weak[np.flatnonzero(~system.excluded)[len(layer.nodes) // 2]] = True
    def layer_of(matrix, weak):
        return BoundaryLayer.on(layout_of(matrix, system.excluded, weak, mass.preconditioner.lattice_shape, first), matrix)

    other = layer_of(system.matrix, weak)
    assert other.layout is not first
    compact = matrix.copy()
    compact.eliminate_zeros()
    assert compact.nnz < matrix.nnz
    moved = layer_of(compact, mass._weak)
    assert moved.layout is not first and np.array_equal(moved.nodes, layer.nodes)
    np.testing.assert_allclose(moved.factors.solve(rhs)[layer.nodes], expected, rtol=0,
                               atol=1e-12 * np.abs(expected).max())
    swapped = matrix.copy()  # one layer row's first two entries in the other order: the same matrix
    start = swapped.indptr[layer.nodes[0]]
    for array in (swapped.indices, swapped.data):
        array[start], array[start + 1] = array[start + 1], array[start]
    assert not first.fits(swapped, system.excluded, system.excluded | mass._weak)
    reordered = layer_of(swapped, mass._weak)
    np.testing.assert_allclose(reordered.factors.solve(rhs)[layer.nodes], expected, rtol=0,
                               atol=1e-12 * np.abs(expected).max())


def test_boundary_layer_on_both_engines():
    """Cubic splines' block of 2.5e3 points on tensor CG with its boundary layer, 6 steps: the
    scipy engine, whose systems are new CSR matrices every step, keeps its layer's layout as
    the compiled engine does (the same index arrays' values) without keeping those arrays alive
    (the compiled engine's stay: its system is made in place), with the same CG iterations, and
    the points' velocities agree to 1e-12 of the largest (3e-14 measured)."""
    runs = {}
    for engine in ("numba", "scipy"):
        simulation = Simulation(block_scene("bspline3", "consistent", 2500).with_overrides(**{
            "solver.linear_solver": "cg", "solver.engine": engine}))
        for step in range(6):
            simulation.advance()
            if step == 3:
                layout = simulation.mass._layer_layouts[((0, 1), False)]
        assert simulation.mass._layer_layouts[((0, 1), False)] is layout
        matrix = simulation.mass._systems[0].matrix
        assert (layout.structure[0]() is matrix.indptr) == (engine == "numba")
        assert (layout.structure[0]() is None) == (engine == "scipy")
        runs[engine] = simulation
    assert runs["numba"].mass.iterations == runs["scipy"].mass.iterations
    v = runs["numba"].particles.v
    assert np.abs(runs["scipy"].particles.v - v).max() <= 1e-12 * np.abs(v).max()


def test_a_blended_system_keeps_its_layer_layouts(monkeypatch):
    """Cubic splines' block with one point per cell, whose consistent mass is singular at every
    step and blended: the layouts of the singular system's layer and of the blended one's are
    analysed at the first step and kept apart, none in the four steps after it."""
    from femgrid_mpm.mass.preconditioners import LayerLayout

    made = []
    analyse = LayerLayout.of.__func__
    monkeypatch.setattr(LayerLayout, "of", classmethod(lambda cls, *a: made.append(1) or analyse(cls, *a)))
    simulation = Simulation(block_scene("bspline3", "consistent", 2500).with_overrides(**{
        "solver.linear_solver": "cg", "bodies.0.points_per_cell": 1}))
    simulation.advance()
    first = len(made)
    for _ in range(4):
        simulation.advance()
    assert simulation.mass.blended_steps == 5 and first == 2 and len(made) == first
    assert set(simulation.mass._layer_layouts) == {((0, 1), False), ((0, 1), True)}


def test_no_boundary_layer_for_a_thin_body():
    """A body 3 cells thick lies within the layer's width of its edges everywhere: the
    layer would hold every kept node (above LAYER_LIMIT), so it is not built, and CG
    with the tensor preconditioner alone still solves the system."""
    from femgrid_mpm.mass.preconditioners import LAYER_LIMIT
    from femgrid_mpm.scene import Scene

    scene = Scene.model_validate({
        "grid": {"basis": "bspline3", "lower": [0, 0], "upper": [20, 7], "spacing": 1.0},
        "time": {"dt": 0.01, "end": 1.0},
        "solver": {"mass": "consistent", "linear_solver": "cg"},
        "bodies": [{"name": "strip", "lower": [2, 2], "upper": [18, 5], "points_per_cell": 3,
                    "velocity": ["0.01*sin(pi*(x-2)/16)", "0"], "material": {"E": 1e4, "nu": 0.3, "density": 1e3}}],
    })
    simulation = Simulation(scene)
    simulation.advance()
    mass = simulation.mass
    system = mass._systems[0]
    assert system.boundary_layer(mass.preconditioner.lattice_shape, mass._weak) is None
    assert LAYER_LIMIT < 1
    rhs = np.where(system.excluded[:, None], 0.0, simulation.context.force)
    solution, converged = mass._solve(system, rhs, "check")
    expected = spla.spsolve(system.matrix.tocsc(), rhs)
    assert converged
    np.testing.assert_allclose(solution, expected, rtol=0, atol=1e-5 * np.abs(expected).max())


def test_a_layer_that_is_not_positive_definite_falls_back_to_the_tensor_preconditioner(monkeypatch):
    """CG stops as soon as ``r.z < 0`` (``converged`` None); the solve then runs again
    with the tensor preconditioner alone and still reaches SuperLU's solution."""
    from femgrid_mpm.mass.system import _System

    class Negative:
        def sweep(self, r, tensor):
            return -_apply_tensor(np.ascontiguousarray(r), np.empty_like(r), *tensor)

    simulation = Simulation(block_scene("bspline3", "consistent", 400))
    mass = simulation.mass
    mass.linear_solver = "cg"
    mass.tolerance = 1e-12
    simulation.advance()
    monkeypatch.setattr(_System, "boundary_layer", lambda self, shape, weak, layouts=None: Negative())
    system = mass._systems[0]
    rhs = np.where(system.excluded[:, None], 0.0, simulation.context.force)
    tensor = mass.preconditioner.scaled(system)
    assert _preconditioned_cg(system.matrix, rhs, np.zeros_like(rhs), system.inverse_diagonal, 1e-12, 100,
                              tensor, Negative())[1] is None
    solution, converged = mass._solve(system, rhs, "check")
    assert converged
    expected = spla.spsolve(system.matrix.tocsc(), rhs)
    np.testing.assert_allclose(solution, expected, rtol=0, atol=1e-9 * np.abs(expected).max())


def test_benchmark_scene_is_the_intended_block():
    simulation = Simulation(block_scene("q1", "lumped", 1000))
    assert simulation.particles.n == 16 * 16 * 4
    assert simulation.active_effects == []
    simulation.advance()


@pytest.mark.filterwarnings("ignore::femgrid_mpm.diagnostics.NegativeMassWarning")
@pytest.mark.parametrize("mass", ["lumped", "hrz", "consistent"])
@pytest.mark.parametrize("basis", ["q1", "q2", "serendipity", "bspline3"])
def test_threaded_kernels_agree_with_serial_ones(basis, mass):
    """solver.threads = 2: the chunked kernels (tensor and folded) give the serial results to
    rounding (consistent mass: its force pass and G2P are chunked)."""
    serial = Simulation(block_scene(basis, mass, 1000))
    threaded = Simulation(block_scene(basis, mass, 1000).with_overrides(**{"solver.threads": 2}))
    assert threaded.transfer.threads == 2
    for _ in range(5):
        serial.advance()
        threaded.advance()
        for name in ("x", "v", "stress", "density"):
            expected, actual = getattr(serial.particles, name), getattr(threaded.particles, name)
            np.testing.assert_allclose(actual, expected, rtol=0, atol=1e-12 * np.abs(expected).max(), err_msg=name)
            getattr(threaded.particles, name)[:] = expected


def test_threaded_runs_depend_on_the_count_asked_for_not_the_machines():
    """solver.threads = 3 cuts the points into 3 chunks whatever numba has: the same bits with
    1 and 2 threads available (the count was capped at the machine's, which changed the sums'
    grouping: a scene's result depended on NUMBA_NUM_THREADS)."""
    import hashlib
    import os
    import subprocess

    script = ("import sys, hashlib; sys.path.insert(0, 'benchmarks'); from step import block_scene; "
              "from femgrid_mpm.solver import Simulation; "
              "s = Simulation(block_scene('q2', 'hrz', 1000).with_overrides(**{'solver.threads': 3})); "
              "[s.advance() for _ in range(5)]; "
              "print(s.transfer.threads, hashlib.sha256(s.particles.x.tobytes() + s.particles.v.tobytes()).hexdigest())")
    root = Path(__file__).parents[1]
    outputs = []
    for available in ("1", "2"):
        env = {**os.environ, "NUMBA_NUM_THREADS": available}
        done = subprocess.run([sys.executable, "-c", script], cwd=root, env=env, capture_output=True, text=True,
                              timeout=600)
        assert done.returncode == 0, done.stderr
        outputs.append(done.stdout.split())
    assert outputs[0] == outputs[1] and outputs[0][0] == "3"
    serial = Simulation(block_scene("q2", "hrz", 1000))
    for _ in range(5):
        serial.advance()
    assert hashlib.sha256(serial.particles.x.tobytes() + serial.particles.v.tobytes()).hexdigest() != outputs[0][1]


def test_minimal_q1_step_is_the_library_step():
    """`benchmarks/minimal_q1.py`, the yardstick `benchmarks/step.py` times beside the
    library, computes the library's q1 lumped step: from the same state, five steps agree
    to 1e-12 of each field's scale (the library works in a moving frame: rounding only)."""
    import minimal_q1

    simulation = Simulation(block_scene("q1", "lumped", 400))
    p, material = simulation.particles, simulation.materials[0]
    side = int(round(np.sqrt(p.n / 4)))
    state = minimal_q1.block(side)
    assert state["x"].shape == p.x.shape and simulation.grid.n_nodes == len(state["grid_mass"])
    for name in ("x", "v", "mass", "density", "stress", "strain"):
        state[name] = getattr(p, name).copy()
    assert np.isclose(state["lame_lambda"], material.lame_lambda) and np.isclose(state["two_mu"],
                                                                                 2 * material.shear_modulus)
    state["lame_lambda"], state["two_mu"] = material.lame_lambda, 2 * material.shear_modulus
    for _ in range(5):
        simulation.advance()
    minimal_q1.run(state, steps=5, dt=simulation.dt)
    for name in ("x", "v", "density", "stress", "strain"):
        expected = getattr(p, name)
        np.testing.assert_allclose(state[name], expected, rtol=0, atol=1e-12 * np.abs(expected).max(), err_msg=name)
    # and the displacement, which is what the step changes: to 1e-9 of its own scale
    displacement = p.x - p.x0
    np.testing.assert_allclose(state["x"] - p.x0, displacement, rtol=0, atol=1e-9 * np.abs(displacement).max())

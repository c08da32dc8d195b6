"""The compiled engine against the scipy reference: shape functions and whole steps.

The numba kernels evaluate the same polynomials in another (separated)
form and sum in the same order where it matters, so everything agrees to
rounding: 1e-12 relative to each quantity's scale, per step, for every basis
and both mass kinds.
"""

import numpy as np
import pytest

from femgrid_mpm import Grid
from femgrid_mpm.bases import BASES
from femgrid_mpm.kernels.shape_matrices import evaluate_shape_functions, shape_function_data
from femgrid_mpm.kernels.tables import LINEAR, separated_tables
from femgrid_mpm.scene import Scene
from femgrid_mpm.solver import Simulation
from helpers import benchmark_block

BASIS_NAMES = list(BASES)


def points_of(grid, n=400, seed=0):
    rng = np.random.default_rng(seed)
    points = grid.lower + rng.random((n, 2)) * (grid.upper - grid.lower)
    # corners, edges and lattice lines: the element choice at ties must match
    lattice = grid.lower + grid.spacing * rng.integers(0, 2 * grid.cells[0], size=(40, 2)) / 2
    lattice = np.minimum(lattice, grid.upper)
    return np.vstack([points, lattice, [grid.lower, grid.upper, [grid.lower[0], grid.upper[1]]]])


@pytest.mark.parametrize("basis", BASIS_NAMES)
def test_compiled_shape_functions_match_the_grid(basis):
    grid = Grid(basis, (-1.0, 0.5), (3.0, 2.5), 0.25)
    points = points_of(grid)
    tables = separated_tables(grid)
    n, n_local = len(points), tables.n_local
    values, d_x, d_y = (np.empty((n, n_local)) for _ in range(3))
    nodes = np.empty((n, n_local), dtype=np.int32)
    N, dNdx, dNdy = grid.shape_functions(points)
    scale = 1.0 / grid.discretization.element_width  # gradients are O(1 / width)
    calls = {  # the flat kernel (any basis) and the fastest one for this basis
        "flat": lambda *out: shape_function_data(points, *tables.arrays(), *out),
        "fastest": lambda *out: evaluate_shape_functions(tables, points, *out),
    }
    for call in calls.values():
        values[:], d_x[:], d_y[:], nodes[:] = np.nan, np.nan, np.nan, -1
        assert call(values, d_x, d_y, nodes) == -1
        np.testing.assert_array_equal(nodes.ravel(), N.indices)
        np.testing.assert_allclose(values.ravel(), N.data, rtol=0, atol=1e-12)
        np.testing.assert_allclose(d_x.ravel(), dNdx.data, rtol=0, atol=1e-12 * scale)
        np.testing.assert_allclose(d_y.ravel(), dNdy.data, rtol=0, atol=1e-12 * scale)


def test_tensor_kernels_cover_the_tensor_bases():
    """q1, q2, both cubic splines and the open-knot quadratic ones take the unrolled tensor kernels;
    serendipity the folded ones; the bases on pieces finer than the node lattice (gimp, the
    quadratic splines with the extra column), whose nodes are no affine function of the piece,
    the flat ones."""
    tables = {name: separated_tables(Grid(name, (0, 0), (2, 2), 0.5)) for name in BASIS_NAMES}
    assert {name for name, t in tables.items() if t.tensor is not None} == {"q1", "q2", "bspline3", "bspline3_open",
                                                                             "bspline2_open"}
    assert {name for name, t in tables.items() if t.tensor is None and t.folded is None} == {"gimp", "bspline2"}
    assert {name for name, t in tables.items() if t.folded is not None} == {"serendipity"}
    # and q1's factors, exactly (1 - s, s), are computed as such (the values: the tests above)
    assert {name for name, t in tables.items() if t.tensor is not None and t.tensor.marker == LINEAR} == {"q1"}


@pytest.mark.parametrize("columns", [1, 2, 3])
def test_compiled_matrix_product_matches_scipy(columns):
    """The compiled row-by-row product (four partial sums per row for two columns) of a
    ``_CompiledCSR`` with no symmetric half against scipy's."""
    import scipy.sparse as sp

    from femgrid_mpm.mass.sparse import _CompiledCSR

    rng = np.random.default_rng(3)
    matrix = sp.random(40, 40, density=0.3, random_state=4, format="csr")
    x = rng.standard_normal((40, columns))
    out = _CompiledCSR(matrix) @ x
    np.testing.assert_allclose(out, matrix @ x, rtol=0, atol=1e-14 * np.abs(matrix @ x).max())


@pytest.mark.parametrize("basis", BASIS_NAMES)
def test_compiled_shape_functions_flag_points_outside(basis):
    grid = Grid(basis, (0.0, 0.0), (2.0, 1.0), 0.5)
    tables = separated_tables(grid)
    points = np.array([[0.5, 0.5], [1.0, 0.2], [2.0 + 1e-9, 0.5], [np.nan, 0.5]])
    buffers = [np.empty((4, tables.n_local)) for _ in range(3)]
    assert shape_function_data(points, *tables.arrays(), *buffers, np.empty((4, tables.n_local), np.int32)) == 2


# -- whole steps: the numba engine against the scipy reference ------------------------------------------


def block_scene(basis, mass, engine, material=None, **extra):
    data = {
        "grid": {"basis": basis, "lower": [0, 0], "upper": [4, 3], "spacing": 0.5},
        "time": {"dt": 0.002, "end": 1.0},
        "solver": {"mass": mass, "negative_mass": "warn", "consistent_fallback": "blend", "engine": engine},
        "bodies": [{"name": "block", "lower": [0.75, 0.5], "upper": [2.75, 1.5], "points_per_cell": 3,
                    "velocity": ["0.3*cos(pi*x/2)", "0.2*sin(pi*y)"],
                    "material": material or {"E": 1e4, "nu": 0.3, "density": 1e3}}],
    }
    data.update(extra)
    return Scene.model_validate(data)


STATE = ("x", "v", "stress", "strain", "density", "deformation_gradient")


def assert_steps_agree(reference, compiled, steps, rtol=1e-12):
    """Per step from the same state: every field agrees to rtol of its own scale."""
    for _ in range(steps):
        reference.advance()
        compiled.advance()
        for name in STATE:
            expected, actual = getattr(reference.particles, name), getattr(compiled.particles, name)
            np.testing.assert_allclose(actual, expected, rtol=0, atol=rtol * np.abs(expected).max(), err_msg=name)
            getattr(compiled.particles, name)[:] = expected  # the next step starts from the same state
        for name in ("momentum", "force"):
            expected, actual = getattr(reference.context, name), getattr(compiled.context, name)
            np.testing.assert_allclose(actual, expected, rtol=0, atol=rtol * np.abs(expected).max(), err_msg=name)
        # v = M^-1 p and a = M^-1 f: where the mass matrix is ill-conditioned (a q2
        # mass nearly cancelling, a weakly supported spline) the rounding of p and f
        # is amplified, so compare M v and M a against the scale of p and f
        for name, rhs in (("velocity", "momentum"), ("acceleration", "force")):
            difference = getattr(compiled.context, name) - getattr(reference.context, name)
            scale = np.abs(getattr(reference.context, rhs)).max()
            np.testing.assert_allclose(reference.mass.apply(difference), 0.0, rtol=0, atol=rtol * scale, err_msg=name)


@pytest.mark.filterwarnings("ignore::femgrid_mpm.diagnostics.NegativeMassWarning")
@pytest.mark.parametrize("mass", ["lumped", "consistent", "hrz"])
@pytest.mark.parametrize("basis", BASIS_NAMES)
def test_engines_agree_per_step(basis, mass):
    reference = Simulation(block_scene(basis, mass, "scipy"))
    compiled = Simulation(block_scene(basis, mass, "numba"))
    assert_steps_agree(reference, compiled, steps=8)


@pytest.mark.parametrize("basis, mass", [("q1", "lumped"), ("bspline3", "lumped"), ("q2", "hrz"),
                                         ("serendipity", "hrz")])
def test_engines_agree_with_other_materials_and_every_effect(basis, mass):
    """Neo-Hookean (the general, non-fused path), gravity and a point load (which
    read ctx.N, or HRZ's weights built from it), damping and supports."""
    extra = dict(
        material={"model": "neo_hookean", "E": 1e4, "nu": 0.3, "density": 1e3},
        loads=[{"kind": "gravity", "acceleration": [0.0, -9.81]},
               {"kind": "point", "body": "block", "at": [2.75, 1.5], "force": [0.0, -50.0], "ramp": 0.01}],
        damping={"kind": "mass", "coefficient": 0.5},
        supports=[{"where": "x <= 0.5", "fix": ["x", "y"]}],
        output={"every": 2},
    )
    reference = Simulation(block_scene(basis, mass, "scipy", **extra))
    compiled = Simulation(block_scene(basis, mass, "numba", **extra))
    assert_steps_agree(reference, compiled, steps=6)
    np.testing.assert_allclose(compiled.energy.table()["total"], reference.energy.table()["total"], rtol=1e-10)


def test_whole_runs_agree():
    """Errors do not grow out of hand over a run (200 steps, no state copied back)."""
    reference = Simulation(block_scene("bspline3", "lumped", "scipy", time={"dt": 0.002, "end": 0.4}))
    compiled = Simulation(block_scene("bspline3", "lumped", "numba", time={"dt": 0.002, "end": 0.4}))
    a, b = reference.run(), compiled.run()
    np.testing.assert_allclose(b.particles.x, a.particles.x, rtol=0, atol=1e-12)
    np.testing.assert_allclose(b.particles.stress, a.particles.stress, rtol=0, atol=1e-9 * np.abs(a.particles.stress).max())


@pytest.mark.filterwarnings("ignore::femgrid_mpm.diagnostics.NegativeMassWarning")
@pytest.mark.parametrize("basis", BASIS_NAMES)
def test_shape_function_matrices_on_demand(basis):
    """The numba engine builds ctx.N, dNdx, dNdy only when read: the same matrices
    as the grid's, each owning its index arrays, refilled after scipy sorted one."""
    simulation = Simulation(block_scene(basis, "lumped", "numba"))
    ctx = simulation.project()
    matrices = (ctx.N, ctx.dNdx, ctx.dNdy)
    expected = simulation.grid.shape_functions(simulation.particles.x)
    for ours, theirs in zip(matrices, expected):
        np.testing.assert_allclose(ours.toarray(), theirs.toarray(), rtol=0, atol=1e-12)
    assert len({id(m.indices) for m in matrices}) == 3 and len({id(m.indptr) for m in matrices}) == 3
    for matrix in matrices:
        abs(matrix)
        matrix.sort_indices()
    for ours, theirs in zip(matrices, expected):
        np.testing.assert_allclose(ours.toarray(), theirs.toarray(), rtol=0, atol=1e-12)
    simulation.advance()  # the points move: the matrices follow them when read again
    ctx = simulation.project()
    np.testing.assert_allclose(ctx.N.toarray(), simulation.grid.shape_functions(simulation.particles.x)[0].toarray(),
                               rtol=0, atol=1e-12)


def test_point_leaving_the_grid_is_named_alike():
    messages = []
    for engine in ("scipy", "numba"):
        scene = block_scene("q1", "lumped", engine, bodies=[{
            "name": "block", "lower": [0.75, 0.5], "upper": [1.75, 1.5], "velocity": [10.0, 0.0],
            "material": {"E": 1e4, "nu": 0.3, "density": 1e3}}], time={"dt": 0.01, "end": 1.0})
        with pytest.raises(Exception, match="a particle left the grid") as stop:
            Simulation(scene).run()
        messages.append(str(stop.value))
    assert messages[0] == messages[1]


@pytest.mark.parametrize("basis", ["q1", "q2", "bspline3"])
def test_engines_agree_with_conjugate_gradients(basis):
    """Large grids solve the consistent mass by CG: the compiled CG on the matrix
    assembled in the P2G pass follows the reference's iterations."""
    reference = Simulation(block_scene(basis, "consistent", "scipy"))
    compiled = Simulation(block_scene(basis, "consistent", "numba"))
    for simulation in (reference, compiled):
        simulation.mass.linear_solver = "cg"
        simulation.mass.tolerance = 1e-12  # far tighter than the default 1e-6: the engines, not the tolerance, are compared
    # each CG stops at a relative residual of 1e-12, so the two solutions differ by up
    # to that times the condition number (q2: the blend, see the next test)
    assert_steps_agree(reference, compiled, steps=4, rtol=1e-8)
    assert compiled.mass.iterations > 0


def assert_solvers_agree(scene, steps, rtol=1e-9, blended_every_step=False):
    """SuperLU and CG (to 1e-12) per step from the same state: the same decisions to
    blend and the same fields to ``rtol`` of each field's scale."""
    direct, iterative = Simulation(scene), Simulation(scene)
    direct.mass.linear_solver = "direct"
    iterative.mass.linear_solver = "cg"
    iterative.mass.tolerance = 1e-12
    for step in range(1, steps + 1):
        direct.advance()
        iterative.advance()
        assert direct.mass.blended_steps == iterative.mass.blended_steps, step
        if blended_every_step:
            assert direct.mass.blended_steps == step
        for name in STATE:
            expected, actual = getattr(direct.particles, name), getattr(iterative.particles, name)
            np.testing.assert_allclose(actual, expected, rtol=0, atol=rtol * np.abs(expected).max(),
                                       err_msg=f"{name}, step {step}")
            getattr(iterative.particles, name)[:] = expected
    return direct


@pytest.mark.parametrize("motion", ["moving", "at rest under gravity"])
@pytest.mark.parametrize("basis", ["q2", "serendipity"])
def test_conjugate_gradients_blend_a_singular_mass_matrix_as_the_direct_solver_does(basis, motion):
    """The block fills its q2 and serendipity elements partly: M is singular every step.
    The direct solver finds the pivot and blends; CG, which solves a momentum (or
    gravity's force) anyway, as both lie in M's range, checks the block near the
    edges and blends too, so the two agree.  Before, CG's velocity kept whatever its
    first guess held in M's null space: stresses O(1) off the direct solver's after one
    step (q2: 26.5 vs 22.7 Pa); at rest under gravity CG blended nothing at step 0 and
    the velocities differed by 14-20%."""
    extra = {}
    if motion != "moving":
        extra = {"loads": [{"kind": "gravity", "acceleration": [0.0, -9.81]}]}
    scene = block_scene(basis, "consistent", "numba", **extra)
    if motion != "moving":
        scene = scene.with_overrides(**{"bodies.0.velocity": [0.0, 0.0]})
    assert_solvers_agree(scene, steps=3, blended_every_step=True)


def test_conjugate_gradients_find_a_singular_mass_matrix_at_the_grid_edge():
    """A q2 body leaving the grid's edge fills the elements there partly, with no empty
    node beside them: steps 19 and 20 are singular (scaled eigenvalues 1e-12 of the
    largest), and the edge check blends them as SuperLU does (before it looked next to
    empty nodes only, missed them, and the stresses differed by 9.6e3 of their scale)."""
    scene = Scene.model_validate({
        "grid": {"basis": "q2", "lower": [0, 0], "upper": [12, 6], "spacing": 0.5},
        "time": {"dt": 0.002, "end": 1.0},
        "solver": {"mass": "consistent", "negative_mass": "warn", "consistent_fallback": "blend", "engine": "numba"},
        "bodies": [{"name": "b", "lower": [0.0, 0.0], "upper": [5.0, 4.0], "points_per_cell": 3,
                    "velocity": ["20 + 0.3*cos(x)", "0.2*sin(y)"],
                    "material": {"E": 1e4, "nu": 0.3, "density": 1e3}}],
    })
    direct = assert_solvers_agree(scene, steps=22, rtol=1e-7)
    assert 0 < direct.mass.blended_steps < 22


@pytest.mark.filterwarnings("ignore::femgrid_mpm.diagnostics.NegativeMassWarning")
@pytest.mark.parametrize("mass", ["lumped", "consistent", "hrz"])
def test_flat_kernels_serve_a_basis_with_no_special_form(monkeypatch, mass):
    """Every registered basis has a tensor or folded form; a new one without either
    runs on the flat kernels.  Serendipity forced onto them agrees with the reference,
    and the folded kernels agree with the flat ones bit for bit in the weights."""
    import dataclasses

    import femgrid_mpm.engines.numba_engine as engines

    reference = Simulation(block_scene("serendipity", mass, "scipy"))
    folded = Simulation(block_scene("serendipity", mass, "numba"))
    original = engines.separated_tables
    monkeypatch.setattr(engines, "separated_tables", lambda grid: dataclasses.replace(original(grid), folded=None))
    flat = Simulation(block_scene("serendipity", mass, "numba"))
    assert (folded.transfer.family, flat.transfer.family) == ("folded", "flat")
    assert_steps_agree(reference, flat, steps=4)
    folded.advance()
    flat.particles.x[:] = folded.particles.x  # compare one step from the same state
    flat.particles.v[:] = folded.particles.v
    folded.advance()
    flat.advance()
    np.testing.assert_array_equal(flat.transfer.grid_mass, folded.transfer.grid_mass)


def _iterations_of(simulation, kind: str, steps: int) -> list[int]:
    """CG's iterations of each ``kind`` solve ("velocity" or "acceleration") in ``steps`` steps."""
    counts, solve = [], simulation.mass.solve

    def counted(rhs, kind_of="velocity", frame=None):
        before = simulation.mass.iterations
        solution = solve(rhs, kind_of, frame=frame)
        if kind_of == kind:
            counts.append(simulation.mass.iterations - before)
        return solution

    simulation.mass.solve = counted
    for _ in range(steps):
        simulation.advance()
    return counts


def test_the_velocity_guess_advances_the_last_grid_velocity():
    """CG's first guess of the consistent velocity solve is the last grid velocity
    plus dt times its acceleration, in the new frame (exact for points that keep
    their places): on the benchmark's q1 block it saves iterations against
    extrapolating the last two solutions (measured 3 against 6-7 per solve here with
    Gauss-Seidel CG; 2 against ~11 at 1e5 points with Jacobi), and both reach the
    same state within CG's tolerance."""
    runs = {}
    for advanced in (True, False):
        simulation = Simulation(benchmark_block("q1", "consistent", 400, linear_solver="cg"))
        if not advanced:
            simulation.mass.time_step = None  # falls back to extrapolation
        runs[advanced] = (_iterations_of(simulation, "velocity", 8), simulation.particles.v.copy())
    assert all(a < b for a, b in zip(runs[True][0][2:], runs[False][0][2:]))
    np.testing.assert_allclose(runs[True][1], runs[False][1], rtol=0, atol=1e-6 * np.abs(runs[False][1]).max())


def test_hrz_weights_follow_the_points():
    """HRZ's weight matrix, built when gravity asks for it, is dropped when the points
    move: read between steps it is the one of the points' new places."""
    from femgrid_mpm.mass import positive_weights

    simulation = Simulation(block_scene("q2", "hrz", "numba", loads=[{"kind": "gravity", "acceleration": [0.0, -9.81]}]))
    simulation.advance()
    simulation.advance()
    expected = positive_weights(simulation.grid.shape_functions(simulation.particles.x)[0])
    assert abs(simulation.context.transfer_weights - expected).max() < 1e-14


@pytest.mark.parametrize("basis", BASIS_NAMES)
def test_assembled_mass_matrix_is_symmetric_and_matches_the_product(basis):
    """The P2G kernels assemble the upper half of ``N.T diag(m) N`` in stencil order and
    copy the rest from the transposes: the matrix is symmetric bit for bit, and agrees
    with scipy's product of the same points' ``N`` to 1e-12 of its largest entry.  The
    fast path (consecutive slots) serves q1 and the tensor splines; q2 (middle node last in
    its 1D order), serendipity (folded kernels), the flat kernels (gimp, bspline2) and the
    incomplete rows at the grid's edge take the general one."""
    import scipy.sparse as sp

    scene = block_scene(basis, "consistent", "numba")
    # no weakly supported nodes or rows: their lumping changes M's entries
    scene = scene.model_copy(update={"solver": scene.solver.model_copy(update={"weak_fraction": 0.0, "weak_ratio": 0.0})})
    simulation = Simulation(scene)
    simulation.advance()
    simulation.particles.x += 0.013  # off the seeding lattice: partly filled rows everywhere
    simulation.project()
    engine, p = simulation.transfer, simulation.particles
    # M itself, rebuilt from the solve's system (made from the pattern's entries in place)
    assert simulation.mass._correction is not None
    assembled = sp.csr_matrix(simulation.mass.matrix)
    assert engine._ordered == (basis in ("q1", "bspline3", "bspline3_open", "bspline2_open"))
    assert (assembled != assembled.T).nnz == 0
    N = simulation.grid.shape_functions(p.x)[0]
    product = (N.T @ sp.diags(p.mass) @ N).toarray()
    np.testing.assert_allclose(assembled.toarray(), product, rtol=0, atol=1e-12 * np.abs(product).max())


def test_density_factor_is_exp_within_one_ulp():
    """Eq. 21's ``exp(-dt div v)`` by its series below 2^-7 (inline, no libm call): at most
    1 ulp from ``math.exp`` at every magnitude up to the bound, equal to it beyond
    and for infinities and NaN."""
    import math

    import numba

    from femgrid_mpm.kernels.g2p import SERIES_BOUND, density_factor

    @numba.njit
    def factors(arguments, out):
        for i in range(arguments.shape[0]):
            out[i] = density_factor(arguments[i])

    rng = np.random.default_rng(7)
    for magnitude in (1e-14, 1e-9, 1e-6, 1e-3, SERIES_BOUND, 0.1, 5.0):
        arguments = rng.uniform(-magnitude, magnitude, 200_000)
        series = np.empty_like(arguments)
        factors(arguments, series)
        libm = np.array([math.exp(a) for a in arguments])
        assert np.max(np.abs(series - libm) / np.spacing(libm)) <= 1.0, magnitude
        if magnitude > SERIES_BOUND:
            outside = np.abs(arguments) > SERIES_BOUND
            np.testing.assert_array_equal(series[outside], libm[outside])
    special = np.array([np.inf, -np.inf, np.nan, 0.0, -0.0, SERIES_BOUND, -SERIES_BOUND])
    out = np.empty_like(special)
    factors(special, out)
    np.testing.assert_array_equal(out[:2], [np.inf, 0.0])
    assert np.isnan(out[2]) and out[3] == out[4] == 1.0
    assert abs(out[5] - math.exp(SERIES_BOUND)) <= np.spacing(out[5])


@pytest.mark.parametrize("basis", ["q1", "serendipity"])
def test_a_zero_density_stops_the_run_by_the_finiteness_check(basis):
    """The passes divide as IEEE 754 does (``kernels.arithmetic.quotient``): a point of zero density
    has an infinite volume, its force is not finite, and the step stops with the one-line
    message that names the step and the first point not finite (numba's default raised
    ZeroDivisionError out of the kernel)."""
    from femgrid_mpm.diagnostics import SimulationStopped

    scene = Scene.model_validate({
        "grid": {"basis": basis, "lower": [0, 0], "upper": [8, 8], "spacing": 1.0},
        "time": {"dt": 1e-3, "end": 1.0},
        "solver": {"mass": "hrz"},
        "bodies": [{"name": "block", "lower": [2, 2], "upper": [6, 6], "points_per_cell": 2,
                    "velocity": ["0.01", "0"], "material": {"E": 1e4, "nu": 0.3, "density": 1e3}}],
    })
    simulation = Simulation(scene)
    simulation.advance()
    simulation.particles.density[5] = 0.0
    with pytest.raises(SimulationStopped) as stop:
        for _ in range(3):
            simulation.advance()
    assert stop.value.reason == "not_finite"
    assert "no longer finite" in str(stop.value) and f"step {stop.value.step}" in str(stop.value)

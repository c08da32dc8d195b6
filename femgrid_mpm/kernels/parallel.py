"""Threaded variants of the transfer kernels (``[solver] threads > 1``).

The points are cut into ``n_chunks`` contiguous chunks, one per thread; each
chunk runs the serial kernel of its pass (:mod:`.p2g`, :mod:`.force`,
:mod:`.g2p`) on its slice, scattering into its own copy of the grid arrays,
and the copies are summed in chunk order.
The result is therefore the same from run to run for a given number of
threads (not bit for bit the serial one: the grid sums are grouped by chunk).

``form`` picks the serial kernel at compile time: ``None`` the tensor-product
ones (q1, q2, cubic splines), a fold (:class:`~.tables.FoldedTables`, a tuple
of floats) the folded ones (serendipity).  Lumped and HRZ mass; consistent
mass and the flat kernels (whose form, a tuple of two arrays, a parallel
region cannot take) stay serial.
"""

from __future__ import annotations

import numba
import numpy as np
from numba import prange
from numba.extending import overload

from .compiled import compiled
from .force import local_linear_elastic_stress_and_force, tensor_linear_elastic_stress_and_force
from .g2p import local_g2p, tensor_g2p
from .p2g import local_p2g_sums, tensor_p2g_sums


def _is_tensor(form) -> bool:
    return isinstance(form, numba.types.NoneType)


def _p2g_chunk(x, v, mass_p, density_p, v_ref, signed, hrz, marker, geometry, n_elements, factors_x, table_x,
               factors_y, table_y, uniform, form, topology, grid_mass, grid_absolute, grid_volume,
               momentum):  # pragma: no cover - replaced by the overload in numba
    """The serial P2G of one chunk (lumped or HRZ): tensor or folded by ``form``."""
    raise NotImplementedError("only callable from compiled code")


@overload(_p2g_chunk, inline="always")
def _p2g_chunk_kernel(x, v, mass_p, density_p, v_ref, signed, hrz, marker, geometry, n_elements, factors_x, table_x,
                      factors_y, table_y, uniform, form, topology, grid_mass, grid_absolute, grid_volume, momentum):
    if _is_tensor(form):
        def tensor(x, v, mass_p, density_p, v_ref, signed, hrz, marker, geometry, n_elements, factors_x, table_x,
                   factors_y, table_y, uniform, form, topology, grid_mass, grid_absolute, grid_volume, momentum):
            return tensor_p2g_sums(x, v, mass_p, density_p, v_ref, signed, False, hrz, marker, geometry, n_elements,
                                   factors_x, table_x, factors_y, table_y, uniform, topology, grid_mass,
                                   grid_absolute, grid_volume, momentum)
        return tensor

    def folded(x, v, mass_p, density_p, v_ref, signed, hrz, marker, geometry, n_elements, factors_x, table_x,
               factors_y, table_y, uniform, form, topology, grid_mass, grid_absolute, grid_volume, momentum):
        return local_p2g_sums(x, v, mass_p, density_p, v_ref, signed, False, hrz, marker, geometry, n_elements,
                              factors_x, table_x, factors_y, table_y, uniform, form, topology, grid_mass,
                              grid_absolute, grid_volume, momentum)
    return folded


def _stress_and_force_chunk(x, velocity, v_ref, relative, dt, mass_p, density_p, body, lame, marker, geometry,
                            n_elements, factors_x, table_x, factors_y, table_y, uniform, form, topology, strain,
                            stress, force, start_motion):  # pragma: no cover - replaced by the overload in numba
    """The serial linear elastic stress and force pass of one chunk: tensor or folded by ``form``."""
    raise NotImplementedError("only callable from compiled code")


@overload(_stress_and_force_chunk, inline="always")
def _stress_and_force_chunk_kernel(x, velocity, v_ref, relative, dt, mass_p, density_p, body, lame, marker, geometry,
                                   n_elements, factors_x, table_x, factors_y, table_y, uniform, form, topology,
                                   strain, stress, force, start_motion):
    if _is_tensor(form):
        def tensor(x, velocity, v_ref, relative, dt, mass_p, density_p, body, lame, marker, geometry, n_elements,
                   factors_x, table_x, factors_y, table_y, uniform, form, topology, strain, stress, force,
                   start_motion):
            return tensor_linear_elastic_stress_and_force(
                x, velocity, v_ref, relative, dt, mass_p, density_p, body, lame, marker, geometry, n_elements,
                factors_x, table_x, factors_y, table_y, uniform, topology, strain, stress, force, start_motion)
        return tensor

    def folded(x, velocity, v_ref, relative, dt, mass_p, density_p, body, lame, marker, geometry, n_elements,
               factors_x, table_x, factors_y, table_y, uniform, form, topology, strain, stress, force,
               start_motion):
        return local_linear_elastic_stress_and_force(
            x, velocity, v_ref, relative, dt, mass_p, density_p, body, lame, marker, geometry, n_elements,
            factors_x, table_x, factors_y, table_y, uniform, form, topology, strain, stress, force, start_motion)
    return folded


def _g2p_chunk(x, v, density_p, acceleration, v_ref, dt, start_motion, hrz, marker, geometry, n_elements, factors_x,
               table_x, factors_y, table_y, uniform, form, topology):  # pragma: no cover - replaced by the overload
    """The serial G2P of one chunk: tensor or folded by ``form``."""
    raise NotImplementedError("only callable from compiled code")


@overload(_g2p_chunk, inline="always")
def _g2p_chunk_kernel(x, v, density_p, acceleration, v_ref, dt, start_motion, hrz, marker, geometry, n_elements,
                      factors_x, table_x, factors_y, table_y, uniform, form, topology):
    if _is_tensor(form):
        def tensor(x, v, density_p, acceleration, v_ref, dt, start_motion, hrz, marker, geometry, n_elements,
                   factors_x, table_x, factors_y, table_y, uniform, form, topology):
            return tensor_g2p(x, v, density_p, acceleration, v_ref, dt, start_motion, hrz, marker, geometry,
                              n_elements, factors_x, table_x, factors_y, table_y, uniform, topology)
        return tensor

    def folded(x, v, density_p, acceleration, v_ref, dt, start_motion, hrz, marker, geometry, n_elements,
               factors_x, table_x, factors_y, table_y, uniform, form, topology):
        return local_g2p(x, v, density_p, acceleration, v_ref, dt, start_motion, hrz, marker, geometry, n_elements,
                         factors_x, table_x, factors_y, table_y, uniform, form, topology)
    return folded


@compiled(forceinline=True)
def _bounds(chunk, n_chunks, n):
    return chunk * n // n_chunks, (chunk + 1) * n // n_chunks


@compiled()
def _sum_parts(parts, out):
    """``out = sum_c parts[c]`` in chunk order (serial: one parallel region per kernel)."""
    flat_out = out.reshape(-1)
    flat_parts = parts.reshape(parts.shape[0], -1)
    for i in range(flat_out.shape[0]):
        total = 0.0
        for c in range(flat_parts.shape[0]):
            total += flat_parts[c, i]
        flat_out[i] = total


@compiled(parallel=True)
def parallel_p2g(x, v, mass_p, density_p, v_ref, signed, hrz,
                 marker, geometry, n_elements, factors_x, table_x, factors_y, table_y, uniform, form, topology,
                 grid_mass, grid_absolute, momentum, mass_parts, absolute_parts, momentum_parts):
    """The lumped or HRZ P2G (:func:`tensor_p2g_sums`, :func:`local_p2g_sums`) over chunks of
    points; returns the first point outside, or -1."""
    n_chunks = mass_parts.shape[0]
    n = x.shape[0]
    outside = np.full(n_chunks, -1)
    no_volume = np.zeros(1)
    for chunk in prange(n_chunks):
        start, stop = _bounds(chunk, n_chunks, n)
        found = _p2g_chunk(x[start:stop], v[start:stop], mass_p[start:stop], density_p[start:stop], v_ref, signed,
                           hrz, marker, geometry, n_elements, factors_x, table_x, factors_y, table_y, uniform, form,
                           topology, mass_parts[chunk], absolute_parts[chunk], no_volume, momentum_parts[chunk])
        if found >= 0:
            outside[chunk] = start + found
    for chunk in range(n_chunks):
        if outside[chunk] >= 0:
            return outside[chunk]
    _sum_parts(mass_parts, grid_mass)
    _sum_parts(momentum_parts, momentum)
    if signed or hrz:  # |N|.T @ m_p, or the HRZ diagonal
        _sum_parts(absolute_parts, grid_absolute)
    return -1


@compiled(parallel=True)
def parallel_stress_and_force(x, velocity, v_ref, relative, dt, mass_p, density_p, body, lame,
                              marker, geometry, n_elements, factors_x, table_x, factors_y, table_y, uniform, form,
                              topology, strain, stress, force, start_motion, force_parts, relative_parts):
    """The linear elastic stress and force pass (:func:`tensor_linear_elastic_stress_and_force`,
    :func:`local_linear_elastic_stress_and_force`) over chunks of points."""
    n_chunks = force_parts.shape[0]
    n = x.shape[0]
    totals = np.zeros(n_chunks)
    for chunk in prange(n_chunks):
        start, stop = _bounds(chunk, n_chunks, n)
        totals[chunk] = _stress_and_force_chunk(
            x[start:stop], velocity, v_ref, relative_parts[chunk], dt, mass_p[start:stop], density_p[start:stop],
            body[start:stop], lame, marker, geometry, n_elements, factors_x, table_x, factors_y, table_y, uniform,
            form, topology, strain[start:stop], stress[start:stop], force_parts[chunk], start_motion[start:stop])
    _sum_parts(force_parts, force)
    relative[:] = relative_parts[0]
    total = 0.0
    for chunk in range(n_chunks):
        total += totals[chunk]
    return total


@compiled(parallel=True)
def parallel_g2p(x, v, density_p, acceleration, v_ref, dt, start_motion, hrz,
                 marker, geometry, n_elements, factors_x, table_x, factors_y, table_y, uniform, form, topology,
                 n_chunks):
    """G2P (:func:`tensor_g2p`, :func:`local_g2p`) over chunks of points (no scatter: nothing to
    combine but the checksum)."""
    n = x.shape[0]
    totals = np.zeros(n_chunks)
    for chunk in prange(n_chunks):
        start, stop = _bounds(chunk, n_chunks, n)
        totals[chunk] = _g2p_chunk(x[start:stop], v[start:stop], density_p[start:stop], acceleration, v_ref, dt,
                                   start_motion[start:stop], hrz, marker, geometry, n_elements, factors_x, table_x,
                                   factors_y, table_y, uniform, form, topology)
    total = 0.0
    for chunk in range(n_chunks):
        total += totals[chunk]
    return total

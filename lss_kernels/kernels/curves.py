"""Sampled curves and quadratic surfaces: the vertex of a parabola through three samples, a
curve's lowest sample and the lowest one away from it, and a quadratic in two variables.

Each is a ``ti.func``; :func:`vertex_offset` is also plain Python, for the host.
"""
import taichi as ti

__all__ = ["curve_minima", "parabola_vertex", "quadratic", "vertex_offset"]


def vertex_offset(below, at, above, min_curvature):
    """Where the parabola through ``(-1, below)``, ``(0, at)``, ``(1, above)`` has its
    vertex: ``(below - above) / (2 (below - 2 at + above))``, or 0 where the second
    difference ``below - 2 at + above`` is not above ``min_curvature`` (a flat or concave
    curve has no minimum there).  Not clipped: at a sample no higher than its neighbours the
    vertex lies within half a step.  Plain Python (the host's, on floats);
    :func:`parabola_vertex` is the same for kernels."""
    den = below - 2.0 * at + above
    t = 0.0
    if den > min_curvature:
        t = 0.5 * (below - above) / den
    return t


#: :func:`vertex_offset` as a ``ti.func``.
parabola_vertex = ti.func(vertex_offset)


@ti.func
def curve_minima(curve: ti.template(), y, x, n, none):
    """The curve ``curve[y, x, k]``, ``k < n``: its lowest value and the first ``k`` that
    has it (``none`` and -1 where no value is below ``none``), the lowest value at least two
    samples from that ``k`` (the second minimum of a peak-ratio test; ``none`` where there
    is none lower) and the sum of its values, in order of ``k``."""
    best, kb, total = none, -1, 0.0
    for k in range(n):
        c = curve[y, x, k]
        total += c
        if c < best:
            best, kb = c, k
    second = none
    for k in range(n):
        if ti.abs(k - kb) >= 2:
            second = ti.min(second, curve[y, x, k])
    return best, kb, second, total


@ti.func
def quadratic(t, x, y):
    """``t . U(x, y)`` with the basis ``U = {x^2, xy, y^2, x, y, 1}`` (Eq. 8's); ``t`` a
    6-vector."""
    return t[0] * x * x + t[1] * x * y + t[2] * y * y + t[3] * x + t[4] * y + t[5]

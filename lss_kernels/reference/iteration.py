"""One full solver iteration in vectorised numpy: the readable specification of
:meth:`lss_kernels.solver.Solver.step`, stage by stage, in float64.

The stages and their order are those of the solver (``solver.STAGES``):

``upward``
    Gaussian-derivative filters of phi (phi_x, phi_y, phi_xx, phi_yy, phi_xy; separable,
    half-width ``ceil(3.5 sigma)``, symmetric borders), the curvature kappa and normal N;
    phi(x + delta_theta) with the previous delta_theta; from the second iteration on, the
    patch sums of D and the patch extremes max phi, min phi(x + delta_theta) at every level
    (what the hierarchy relays upward, computed here directly over each patch's in-image
    pixels).
``messages``
    Eq. 4 (w_p = max phi > 0 XOR min phi_+ < 0) and Eq. 5 (d_p = argmin_c C_p(c) +
    beta |c - <D>_p|, sigma_p = c_max / (mean - min)); at the first iteration every patch is
    valid and there is no prior term.
``downward``
    Eq. 7: 1/sigma^2 and d-bar from every valid patch (of every level) containing the pixel.
``shapes``
    Eq. 8: Theta_1 over phi >= 0 and Theta_2 over the visible background (phi < 0 and
    phi_+ < 0), weighted least squares (:func:`numpy.linalg.lstsq`) of the consensus mean with
    weights (1/sigma^2) ** ``WEIGHT_POWER`` (:mod:`lss_kernels.model.shapes`); a region with
    fewer than 6 weighted rows, or a rank-deficient system, keeps its previous shape.  Then, in the first ``reinit_every``
    iterations and at every re-initialisation, the background's plane sweep (Theta_2 may
    become a fronto-parallel plane).
``occlusion``
    delta_theta by the ray cast of Sec. 2 (fixed-point iteration on
    ``t = Theta_1(x) - Theta_2(x - s t)``, ``s = sign(dphi/dx)``), and phi(x + delta_theta).
``boundary``
    B(x, y, Theta_1(x, y)) = alpha_1 B_occ + alpha_2 B_mono + alpha_3 (linear in c)
    and its Gaussian-derivative gradient.
``levelset``
    The Eq. 2 step, then (every ``reinit_every`` iterations) the signed-distance
    re-initialisation, then the ``median_size``-squared median filter with symmetric
    borders, and D = Theta_1 where the new phi > 0, else Theta_2 (Eq. 3; the kernels write
    it in the median's last pass).

Frames and units are the solver's: cyclopean ``(H, W)`` arrays indexed ``[y, x]``, cyclopean
disparities ``c = 1 .. c_max`` (volume index ``k = c - 1``); Theta over the normalised basis
(``x_n = (x - (W - 1) / 2) / s``, ``y_n = (y - (H - 1) / 2) / s``, ``s = max(H, W) / 2``) in
cyclopean units.

Examples
--------
>>> solver = Solver(left, right, 32, (40, 30, 15, 12), params=params)   # doctest: +SKIP
>>> state = state_from_solver(solver)                                   # doctest: +SKIP
>>> new_state, seconds = iteration(state, params)                       # doctest: +SKIP
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field, replace

import numpy as np

from ..model import FIXED_POINT_STEPS, STAGES
from . import kernels as ref
from ..model.shapes import WEIGHT_POWER
from ..model.sweep import due
from ..params import BOUNDARY_CLIP, CURVATURE_CLIP, CURVATURE_SIGMA, PHI_SCALE
from .sweep import background_sweep

__all__ = ["IterationState", "STAGES", "iteration", "run", "state_from_solver"]


@dataclass
class IterationState:
    """Everything one iteration reads (and, for the evolving part, writes).

    Constant over a solve: ``costs`` (per level, the in-image ``(H, W, c_max)`` min-max
    normalised patch-mean matching cost C_p(c); level 0 is the size-3 cost M of Eq. 2),
    ``b_occ`` ``(H, W, c_max)``, ``edge_left`` and ``edge_right`` ``(H, W)`` (edge scores of
    B_mono).  Evolving: ``phi``, ``D``, ``delta_theta`` ``(H, W)``, ``theta`` ``(2, 6)`` and
    ``iteration`` (iterations done).  ``extra`` holds the diagnostics of the last iteration
    (``consensus_mean``, ``precision``, ``phi_plus``, ``flipped``, ``area``, ...).
    """

    costs: list
    b_occ: np.ndarray
    edge_left: np.ndarray
    edge_right: np.ndarray
    phi: np.ndarray
    D: np.ndarray
    delta_theta: np.ndarray
    theta: np.ndarray
    iteration: int = 0
    extra: dict = field(default_factory=dict)

    @property
    def shape(self):
        return self.phi.shape

    @property
    def c_max(self):
        return self.costs[0].shape[2]

    @property
    def nbytes_levels(self):
        """Bytes of the level cost volumes in float32 (what the kernels stream)."""
        return sum(4 * c.size for c in self.costs)


def state_from_solver(solver) -> IterationState:
    """The state of a :class:`~lss_kernels.solver.Solver` (after set-up or any step), as
    float64 numpy arrays; level volumes are cut to their in-image part."""
    H, W = solver.H, solver.W
    h = solver.hierarchy
    costs = []
    for lev in h.levels:
        m = lev.margin
        costs.append(lev.cost.to_numpy()[m:m + H, m:m + W].astype(np.float64))
    f64 = lambda f: solver.extent.image(f).astype(np.float64)
    prec = f64(h.precision)
    return IterationState(
        costs=costs, b_occ=f64(solver.costs.b_occ), edge_left=f64(solver.costs.edge_left),
        edge_right=f64(solver.costs.edge_right), phi=f64(solver.levelset.phi),
        D=f64(solver.levelset.D), delta_theta=f64(solver.occ.delta_theta),
        theta=solver.shapes.theta.to_numpy().astype(np.float64), iteration=int(solver.iteration),
        extra=dict(consensus_mean=f64(h.consensus_mean), precision=prec,
                   phi_plus=f64(solver.occ.phi_plus)))


# ---------------------------------------------------------------------------- the iteration
def iteration(state: IterationState, params):
    """One iteration of the solver (the alternation of Sec. 3), in numpy.

    Parameters
    ----------
    state : IterationState
        The state before the iteration (see :func:`state_from_solver`); not modified.
    params : lss_kernels.Params

    Returns
    -------
    new_state : IterationState
        ``phi``, ``D``, ``delta_theta``, ``theta`` and ``iteration`` updated; ``extra`` holds
        ``consensus_mean`` and ``precision`` ``(H, W)`` (cyclopean units, 1/sigma^2), ``d_p``,
        ``sigma_p``, ``valid`` (lists per level), ``phi_plus``, ``updated`` (which shapes were
        refitted), ``plane`` (the sweep's Theta_2 plane, cyclopean, or None), ``flipped`` and
        ``area``.
    seconds : dict
        Wall-clock seconds per stage (keys :data:`STAGES`).
    """
    p = params
    H, W = state.shape
    C = state.c_max
    sizes = tuple(p.patch_sizes)
    it = state.iteration + 1
    first = it == 1
    seconds = {}
    y, x = np.mgrid[0:H, 0:W].astype(np.float64)
    theta_map = lambda theta_j, xx=x: ref.shape_value(theta_j, xx, y, (H, W))

    # upward: derivatives of phi, phi(x + delta_theta), patch means / extremes
    t = time.perf_counter()
    phi = state.phi
    derivatives = ref.gaussian_derivatives(phi, CURVATURE_SIGMA)
    kappa, nx, ny = ref.curvature(derivatives, CURVATURE_CLIP)
    phi_plus = ref.interp_row(phi, x + state.delta_theta)
    if not first:
        d_mean = [ref.box_mean(state.D, s) for s in sizes]
        phi_max = [ref.box_extreme(phi, s, np.max) for s in sizes]
        phi_plus_min = [ref.box_extreme(phi_plus, s, np.min) for s in sizes]
    now = time.perf_counter()
    seconds["upward"], t = now - t, now

    # messages: Eq. 4 and Eq. 5
    if first:
        valid = [np.ones((H, W), bool) for _ in sizes]
        msgs = [ref.patch_messages(cost, np.zeros((H, W)), 0.0, p.subpixel_messages)
                for cost in state.costs]
    else:
        valid = [(mx > 0) != (mn < 0) for mx, mn in zip(phi_max, phi_plus_min)]
        msgs = [ref.patch_messages(cost, dm, p.beta / C, p.subpixel_messages)
                for cost, dm in zip(state.costs, d_mean)]
    d_p = [m[0] for m in msgs]
    sigma_p = [m[1] for m in msgs]
    now = time.perf_counter()
    seconds["messages"], t = now - t, now

    # downward: Eq. 7
    weights = ([ref.distinctness(cost, p.message_ambiguity) for cost in state.costs]
               if p.message_ambiguity > 0 else None)
    precision, mean = ref.consensus(d_p, sigma_p, valid, sizes, weights)
    now = time.perf_counter()
    seconds["downward"], t = now - t, now

    # shapes: Eq. 8 over the foreground and the visible background
    w = precision ** WEIGHT_POWER
    # a consensus whose correspondence falls outside the other image is no evidence
    w = np.where((x - mean < 0) | (x + mean > W - 1), 0.0, w)
    w_fg = np.where(phi >= 0, w, 0.0)
    w_bg = np.where((phi < 0) & (phi_plus < 0), w, 0.0)
    theta = np.array(state.theta, np.float64, copy=True)
    updated = []
    for j, wj in enumerate((w_fg, w_bg)):
        theta[j], ok = ref.fit_shape(wj, mean, theta[j])
        updated.append(ok)
    plane = None
    if due(it, p):
        plane = background_sweep(state.costs[0], (phi < 0) & (phi_plus < 0),
                                 theta_map(theta[0]), theta_map(theta[1]), mean,
                                 p.background_sweep)
        if plane is not None:
            theta[1] = (0.0, 0.0, 0.0, 0.0, 0.0, plane)
    now = time.perf_counter()
    seconds["shapes"], t = now - t, now

    # occlusion: delta_theta (the ray cast) and phi(x + delta_theta)
    th1, th2 = theta_map(theta[0]), theta_map(theta[1])
    delta_theta = ref.delta_theta(lambda xx, yy: theta_map(theta[0], xx),
                                  lambda xx, yy: theta_map(theta[1], xx), derivatives[0],
                                  FIXED_POINT_STEPS, 2.0 * C)
    phi_plus = ref.interp_row(phi, x + delta_theta)
    now = time.perf_counter()
    seconds["occlusion"], t = now - t, now

    # boundary: B(x, y, Theta_1) and its gradient
    b = ref.boundary_weight(state.b_occ, state.edge_left, state.edge_right, th1,
                            p.alpha)
    b_x, b_y = ref.gaussian_derivatives(b, CURVATURE_SIGMA)[:2]
    now = time.perf_counter()
    seconds["boundary"], t = now - t, now

    # levelset: Eq. 2, re-initialisation, median, Eq. 3
    phi_next = ref.levelset_step(phi, state.costs[0], th1, th2, delta_theta, b, b_x, b_y,
                                 kappa, nx, ny, p.dt, p.mu, BOUNDARY_CLIP,
                                 p.narrow_band * PHI_SCALE)
    if it % p.reinit_every == 0:
        phi_next = ref.reinitialise(phi_next, PHI_SCALE)
    phi_new = ref.median_filter(phi_next, p.median_size)
    flipped = int(((phi_new > 0) != (phi > 0)).sum())
    area = int((phi_new > 0).sum())
    D = ref.disparity(phi_new, th1, th2, C)
    seconds["levelset"] = time.perf_counter() - t

    extra = dict(consensus_mean=mean, precision=precision, d_p=d_p, sigma_p=sigma_p,
                 valid=valid, phi_plus=phi_plus, updated=updated, plane=plane, flipped=flipped,
                 area=area)
    return replace(state, phi=phi_new, D=D, delta_theta=delta_theta, theta=theta,
                   iteration=it, extra=extra), seconds


def run(state: IterationState, params, n: int):
    """``n`` iterations; returns the final state and the summed seconds per stage."""
    total = {s: 0.0 for s in STAGES}
    for _ in range(n):
        state, sec = iteration(state, params)
        for k, v in sec.items():
            total[k] += v
    return state, total

"""The alternation of Sec. 3 (stopping: :mod:`lss_kernels.stopping`); the public ``Solver`` /
``Result`` (``solve``, the checks around a solver: :mod:`lss_kernels.checks.around`).

One iteration (as in the authors' release, with everything a data-parallel kernel):

1. derivatives of phi (normal, curvature, sign of dphi/dx) and phi(x + delta_theta);
2. upward pass: patch means of D, patch extremes of phi and phi(x + delta_theta) -> w_p (Eq. 4);
3. patch messages d_p, sigma_p (Eq. 5; no |c - D| prior and all patches valid at iteration 1);
4. downward pass: the consensus (Eq. 7);
5. Theta_1 over phi >= 0 and Theta_2 over the visible background, by the hierarchical
   normal-equation reduction (Eq. 8), then the background's plane sweep (model/sweep.py):
   ``GlobalShapes.update``;
6. delta_theta for the new Theta (the ray cast of Sec. 2);
7. the Eq. 2 step of phi, then (every ``reinit_every``) signed-distance re-initialisation and
   the median filter;
8. D = H(phi) Theta_1 + (1 - H(phi)) Theta_2 (Eq. 3), written by the median's last pass.

The host reads two integers per iteration (flipped pixels, foreground area), one number per
re-initialisation and two per stop window for the stopping rule, and ``c_max + 2`` numbers
per sweep; nothing else leaves the device inside the loop.
"""
import time
import warnings

import numpy as np
import taichi as ti

from .checks.pair import CheckedPair
from .checks.validate import check_memory, check_params
from .kernels import backend
from .model import STAGES
from .model.appearance import BAND as APPEARANCE_BAND
from .model.front import REACH as FRONT_REACH
from .model.grid import Grid
from .model.layers import FRONT, front_in_left_view, occlusion_by_layers
from .model.offset import SHIFT, model_pair, search_range, to_model_left, to_user_left
from .params import PHI_SCALE, c_max
from .confidence import of_solver
from .result import Result
from .model.start import initial_region
from .start_types import Point, UnreliableStartWarning
from .stopping import StopRule

__all__ = ["Result", "Solver"]


class Solver:
    """A two-layer level-set stereo solve that can be stepped one iteration at a time.

    Parameters
    ----------
    left, right : array ``(H, W[, C])`` or path
        Rectified pair; the left image is the reference.  ``left`` may be a
        :class:`~lss_kernels.checks.pair.CheckedPair`, checked before: the other arguments
        up to ``init_frame`` are then its own.
    d_max : float
        Largest disparity to search, in left-view pixels (cyclopean ``c_max = ceil(d_max /
        2)``; one more for a pair searched from 0 px, :mod:`lss_kernels.model.offset`).
    init : tuple ``(cx, cy, rx, ry)``, boolean array ``(H, W)``, ``"auto"``, Point or Box
        Initial foreground: an ellipse (read as the box around it with
        ``params.refine_ellipse``, :func:`lss_kernels.model.start.region_in_ellipse`) or a
        mask, in the frame ``init_frame``; or found from the first consensus
        (:mod:`lss_kernels.model.init`; ``init_info`` says what was chosen, ``initial_left``
        holds it as a left-view mask).
    params : Params, optional
    arch : str, optional
        Taichi arch; initialises Taichi if given (else uses the current one, or the CPU).
    init_frame : {"left", "cyclopean"}
        Frame of ``init``.  A left-view init is moved to the cyclopean frame by half the
        foreground disparity, estimated as the median consensus mean inside it.
    profile : bool
        Synchronise after every stage to time it (slightly slower).

    Built while no other is open, it restarts Taichi to reuse compiled kernels
    (:func:`~lss_kernels.kernels.backend.fresh_numbering`).

    Examples
    --------
    >>> s = Solver(left, right, 64, (80, 60, 30, 25))          # doctest: +SKIP
    >>> while not s.done:                                      # doctest: +SKIP
    ...     stats = s.step()
    >>> result = s.result()                                    # doctest: +SKIP
    """

    def __init__(self, left, right, d_max, init, params=None, arch=None, init_frame="left",
                 profile=False):
        t_start = time.perf_counter()
        backend.before_solver(arch)
        self.params = check_params(params).for_start(init)
        pair = CheckedPair.of(left, right, d_max, init, init_frame, self.params)
        self.H, self.W = pair.left.shape[:2]
        self.profile = profile
        self.grid, self._grids = None, {}   # the current grid; every grid, by c_max
        self.c_release = c_max(pair.d_max)  # the authors' grid; a pair from 0 px: one more
        self._use(self.c_release)
        self._load(pair, t_start)

    def _use(self, C):
        """Make the grid of ``C`` cyclopean candidates the solve's, zeroed: built the first
        time, kept when another grid is taken up (a solver holds the authors' grid and, once
        a pair was searched from 0 px, the grid of one plane more)."""
        grid = self._grids.get(C)
        if grid is None:
            check_memory(self.H, self.W, 2 * C)    # before a new pool's allocation
            grid = self._grids[C] = Grid(self.H, self.W, C, self.params)
        else:
            grid.pool.zero()
        self.grid = grid

    def __getattr__(self, name):
        """The current grid's fields and stage objects are the solver's: ``solver.hierarchy``
        is ``solver.grid.hierarchy`` (:class:`~lss_kernels.model.grid.Grid`)."""
        grid = self.__dict__.get("grid")
        if grid is None:
            raise AttributeError(f"Solver has no attribute {name!r} (or it is closed)")
        return getattr(grid, name)

    def reset(self, left, right, d_max, init, init_frame="left"):
        """Start over on another pair of the same size and the same ``c_max``, in this
        solver's fields and with its compiled kernels (a new :class:`Solver` compiles its
        kernels again, which takes seconds; use this to solve a sequence of pairs).

        Arguments as for :class:`Solver`; the state is exactly that of a new solver.
        """
        t_start = time.perf_counter()
        if self.grid is None:
            raise RuntimeError("reset: the solver is closed; build a new Solver")
        pair = CheckedPair.of(left, right, d_max, init, init_frame, self.params)
        left, d_max = pair.left, pair.d_max
        if left.shape[:2] != (self.H, self.W) or c_max(d_max) != self.c_release:
            raise ValueError(f"reset: expected a {self.W}x{self.H} pair with ceil(d_max / 2) = "
                             f"{self.c_release} (this solver's fields), got "
                             f"{left.shape[1]}x{left.shape[0]} with d_max {d_max}; build a "
                             f"new Solver for it")
        self._use(self.c_release)
        self._load(pair, t_start)

    def _load(self, pair, t_start):
        """Set-up of a solve in zeroed fields: images, cost volumes, the initial phi."""
        left, d_max, init, init_frame = pair.left, pair.d_max, pair.init, pair.init_frame
        self.pair, self.left_image, self.d_max = pair, left, d_max
        right, self.photometry = pair.right_view(self.params.photometric)

        t0 = time.perf_counter()
        self._load_pair(left, right, 0)
        self._first_consensus()         # from 0 px if it sits at the grid's floor
        self.search = search_range(self.extent.image(self.hierarchy.consensus_mean),
                                   self.extent.image(self.hierarchy.precision),
                                   self.params.zero_floor, self.c_release)
        if self.search["from_zero"]:    # one plane more, in fields of their own
            self._use(self.c_release + 1)
            self._load_pair(left, right, SHIFT)
            self._first_consensus()
        if self.front is not None:
            self.front.capture(self.hierarchy.matching_cost, self.c_max)
        self.costs.build(self.hierarchy.matching_cost, self.left, self.right, self.params)
        self.shapes.sweep.standardise(self.hierarchy.matching_cost)
        ti.sync()
        self.timings = {"setup_costs": time.perf_counter() - t0}
        self.timings.update({s: 0.0 for s in STAGES})

        self.initial_mask = self._initial_mask(init, init_frame)
        self.levelset.start(self.initial_mask, self.c_max)
        self.iteration = 0
        self.done = False
        self.stop_reason = None
        self.history = []
        self._shift = self._surface = None   # no window has ended yet
        self._moved = 0.0
        self._rule = StopRule(self.params)
        self.levelset.net_change()
        self._t_loop = 0.0
        self.timings["setup_total"] = time.perf_counter() - t_start

    @property
    def offset(self):
        """Model disparity less user disparity (lss_kernels.model.offset)."""
        return 2 * self.shift

    def _load_pair(self, left, right, shift):
        """The model's pair for a grid moved by ``shift`` (lss_kernels.model.offset) into the
        image fields, and its matching costs."""
        self.shift = shift
        model_left, model_right = model_pair(left, right, shift)
        self.pool.write(self.left, self.extent.padded(model_left))
        self.pool.write(self.right, self.extent.padded(model_right))
        self.matching.setup(self.left, self.right)
        self.hierarchy.build_costs(self.matching, self.left, self.right)

    # ------------------------------------------------------------------ initialisation
    def _initial_mask(self, init, init_frame):
        """The initial foreground in the cyclopean frame
        (:func:`lss_kernels.model.start.initial_region`); also keeps it in the left view."""
        h = self.hierarchy
        precision = self.extent.image(h.precision)
        # a point's tone (model/init.py): the left view's grey values in the model's frame
        tone = ((to_model_left(self.pair.grey[0], self.shift), precision)
                if isinstance(init, Point) else None)

        def find(start):
            region, frame = self.initialiser.find(start, h.consensus_mean, h.precision,
                                                  periodic=self.pair.periodic_share,
                                                  tone=tone)
            return region, frame, self.initialiser.info, self.initialiser.grown

        mask, self.initial_left, self.init_info = initial_region(
            init, init_frame, self.shift, self.extent.image(h.consensus_mean), precision,
            find, self.params.refine_ellipse)
        if "warning" in self.init_info:
            warnings.warn(UnreliableStartWarning(self.init_info["warning"]), stacklevel=4)
        return mask

    def _first_consensus(self):
        """The consensus (Eq. 7) of messages with no prior (Eq. 5), every patch valid."""
        self.fused.consensus(self.messages.prepare(0.0, False, False), 0)

    # ------------------------------------------------------------------ the iteration
    def _stage(self, name, t):
        if self.profile:
            ti.sync()
            now = time.perf_counter()
            self.timings[name] += now - t
            return now
        return t

    def step(self):
        """Run one iteration; returns its statistics (a dict)."""
        if self.done:
            raise RuntimeError("step: the solver has already stopped "
                               f"({self.stop_reason}); build a new Solver to run again")
        p = self.params
        t = t_iter = time.perf_counter()
        self.iteration += 1
        first = self.iteration == 1
        ls, hier = self.levelset, self.hierarchy
        # without profiling, the stages with nothing on the host between them run as one
        # kernel each (model/iteration.py); profiling times them one by one
        if self.profile:
            ls.derivatives()
            self.occ.refresh_phi_plus(ls.phi)
        else:
            self.fused.derivatives(ls.band)
        if not first:
            hier.upward(ls.D, ls.phi, self.occ.phi_plus)
        t = self._stage("upward", t)
        if self.profile:
            self.messages.run(p.beta / self.c_max, not first, not first)
            t = self._stage("messages", t)
            hier.downward()
            t = self._stage("downward", t)
        else:
            self.fused.consensus(self.messages.prepare(p.beta / self.c_max, not first,
                                                       not first), int(not first))
        plane = self.shapes.update(self.iteration, p, hier.matching_cost)
        if self.front is not None:
            self.front.update(hier.matching_cost, self.c_max, self.shapes, ls.phi,
                              -FRONT_REACH * PHI_SCALE, 0.5 * p.front_margin)
        t = self._stage("shapes", t)
        if self.profile:
            self.occ.compute(self.shapes, ls.phi_x, 1)
            t = self._stage("occlusion", t)
            ls.boundary_weight(self.costs, self.shapes)
            t = self._stage("boundary", t)
        else:
            self.fused.geometry(1, 2.0 * self.c_max)
        reinit = self.iteration % p.reinit_every == 0
        if self.appearance is not None and self.iteration % p.reinit_every == 1:
            self.appearance.update(self.left, self.right, ls.phi, self.shapes, hier.precision,
                                   ls.appearance, p.appearance, APPEARANCE_BAND * PHI_SCALE)
        # the median's last pass also writes D (Eq. 3) from the new phi
        flipped, area = (int(v) for v in ls.evolve(hier.matching_cost, self.c_max, self.shapes,
                                                    self.occ, p, reinit))
        if reinit and p.stop_shift > 0 and p.stop_surface > 0:  # since the last re-init
            self._moved = max(self._moved, 2.0 * float(self.shapes.moved(ls.phi)))
        t = self._stage("levelset", t)
        seconds = time.perf_counter() - t_iter
        self._t_loop += seconds
        if self._rule.is_window_end(self.iteration):
            changed, boundary = (int(v) for v in ls.net_change())
            self._shift = changed / max(boundary, 1)
            self._surface, self._moved = self._moved, 0.0
            self._rule.record(self._shift, self._surface)
        stats = dict(iteration=self.iteration, flipped=flipped, boundary_shift=self._shift,
                     surface_change=self._surface, fg_fraction=area / float(self.H * self.W),
                     seconds=seconds,
                     background_plane=None if plane is None else 2.0 * plane - self.offset)
        self.history.append(stats)
        self._check_stop(area, self._shift)
        return stats

    def _check_stop(self, area, shift):
        p = self.params
        if area == 0:
            self.stop_reason = f"foreground vanished at iteration {self.iteration}"
        elif area == self.H * self.W:
            self.stop_reason = f"foreground filled the image at iteration {self.iteration}"
        elif self._rule.converged(self.iteration):
            bound = ("no label changed" if shift == 0 and self._surface >= p.stop_surface
                     else f"< {p.stop_shift} and {p.stop_surface} px")
            self.stop_reason = (f"converged at iteration {self.iteration}: the boundary "
                                f"shifted by {shift:.3f} px and the surfaces by "
                                f"{self._surface:.2f} px over the last {p.stop_window} "
                                f"iterations ({bound} in "
                                + ("its last window)" if self._rule.quiet == 1 else
                                   f"{self._rule.quiet} windows in a row)"))
        elif self.iteration >= p.max_iterations:
            self.stop_reason = f"reached the iteration cap ({p.max_iterations})"
        self.done = self.stop_reason is not None

    def run(self, callback=None):
        """Step until the stopping rule or the cap; ``callback(solver, stats)`` after each
        iteration (return ``False`` from it to stop early).  Returns :class:`Result`."""
        while not self.done:
            stats = self.step()
            if callback is not None and callback(self, stats) is False:
                self.stop_reason = f"stopped by the callback at iteration {self.iteration}"
                self.done = True
        return self.result()

    # ------------------------------------------------------------------ outputs
    def left_view(self, refine=False):
        """Left-view ``(disparity, occlusion, foreground)`` of the model; with ``refine`` the
        refined disparity (:mod:`lss_kernels.model.refine`; without ``params.refine``, the
        disparity) comes fourth and the strips are measured against it (``strip_window``)."""
        self.occ.render_left(self.shapes, self.levelset.phi)
        refined = self.occ.disparity_left
        if refine and self.refinement is not None:
            t0 = time.perf_counter()
            self.refinement.run(self.left, self.right, self.occ.disparity_left,
                                self.occ.foreground_left, self.occ.occlusion_left,
                                self.d_max + self.offset)
            if self.params.strip_window[1] > 0:
                self.occ.measure_strips(self.refinement.surface, self.refinement.weight,
                                        *self.params.strip_window)
            ti.sync()
            self.timings["refine"] = time.perf_counter() - t0
            refined = self.refinement.surface
        user = lambda plane: to_user_left(self.extent.image(plane), self.shift)  # user frame
        clean = lambda d: np.clip(np.nan_to_num(d, nan=0.0, posinf=0.0, neginf=0.0)
                                  - self.offset, 0.0, self.d_max).astype(np.float32)
        out = (clean(user(self.occ.disparity_left)), user(self.occ.occlusion_left).astype(bool),
               user(self.occ.foreground_left).astype(bool))
        return out + (clean(user(refined)),) if refine else out

    def consensus(self):
        """Consensus mean and sigma, cyclopean frame, left-view disparity units."""
        prec = self.extent.image(self.hierarchy.precision)
        mean = 2.0 * self.extent.image(self.hierarchy.consensus_mean) - self.offset
        with np.errstate(divide="ignore"):
            sigma = np.where(prec > 0, 2.0 / np.sqrt(np.maximum(prec, 1e-30)), self.d_max)
        return mean.astype(np.float32), np.minimum(sigma, self.d_max).astype(np.float32)

    def snapshot(self):
        """Current state as numpy arrays (see :class:`Result` for frames and units)."""
        disparity, occlusion, foreground = self.left_view()
        mean, sigma = self.consensus()
        return dict(phi=self.extent.image(self.levelset.phi), consensus_mean=mean,
                    consensus_sigma=sigma, disparity=disparity, occlusion=occlusion,
                    foreground=foreground, initial_foreground=self.initial_left,
                    D=2.0 * self.extent.image(self.levelset.D) - self.offset)

    def patch_curve(self, level, x, y):
        """Everything about one patch (cyclopean ``x, y``; ``level`` indexes
        ``params.patch_sizes``), in left-view disparity units: the candidates ``d``, C_p(d)
        with the beta |d - D| term (``cost``), the patch-mean matching cost, d_p, sigma_p,
        validity and the patch mean of D."""
        h = self.hierarchy
        x, y = int(x), int(y)
        if not (0 <= level < len(h.levels)) or not (0 <= x < self.W and 0 <= y < self.H):
            raise ValueError(f"patch_curve: level in [0, {len(h.levels) - 1}], x in "
                             f"[0, {self.W - 1}], y in [0, {self.H - 1}] expected, got "
                             f"level={level}, x={x}, y={y}")
        matching = h.patch_cost(level, y, x).astype(np.float64)
        c = np.arange(1, self.c_max + 1, dtype=np.float64)
        lev = h.levels[level]
        d_sum = lev.d_sum[y, x // h.lanes][x % h.lanes]
        d_mean = d_sum / max(h.in_image_count(level, y, x), 1)
        prior = self.iteration > 1
        beta = self.params.beta / self.c_max if prior else 0.0
        cost = matching + beta * np.abs(c - d_mean)
        # the iteration passes messages on as relays only: the same inputs again give the
        # last iteration's d_p, sigma_p and validity
        self.messages.run(beta, prior, prior, keep=True)
        return dict(d=2 * c - self.offset, cost=cost, matching_cost=matching,
                    d_p=2.0 * lev.d_p[y, x] - self.offset, sigma_p=2.0 * lev.sigma_p[y, x],
                    valid=bool(lev.valid[y, x]), mean_D=2.0 * d_mean - self.offset)

    def _front_view(self, surface, occlusion, foreground, disparity):
        """The left-view outputs with the layer in front of the object
        (:mod:`lss_kernels.model.front`) drawn over them, and the layer map: front pixels take
        the first consensus's disparity, leave the object, and hide from the right camera the
        pixels of the layers behind them (:func:`~lss_kernels.model.layers.occlusion_by_layers`)."""
        layers = foreground.astype(np.uint8)
        if self.front is None:
            return surface, occlusion, foreground, disparity, layers
        mask, d_front = front_in_left_view(self.extent.image(self.front.front) > 0,
                                           self.extent.image(self.front.first))
        mask = to_user_left(mask, self.shift)
        d_front = np.clip(to_user_left(d_front, self.shift) - self.offset, 0.0, self.d_max)
        surface = np.where(mask, d_front, surface).astype(np.float32)
        disparity = np.where(mask, d_front, disparity).astype(np.float32)
        layers[mask] = FRONT
        hidden = occlusion_by_layers(disparity, layers, occluders=mask)
        return (surface, (occlusion & ~mask) | hidden, foreground & ~mask, disparity, layers)

    def result(self):
        """The current model as a :class:`Result`."""
        surface, occlusion, foreground, disparity, layers = self._front_view(
            *self.left_view(refine=True))
        mean, sigma = self.consensus()
        th = self.shapes.pixel_coefficients(2.0)
        th[:, 5] -= self.offset
        timings = dict(self.timings)
        timings["iterations_total"] = self._t_loop
        timings["total"] = (self.timings["setup_total"] + self._t_loop
                            + self.timings.get("refine", 0.0))
        return Result(disparity=disparity, surface=surface, occlusion=occlusion,
                      foreground=foreground,
                      phi=self.extent.image(self.levelset.phi), theta_fg=th[0], theta_bg=th[1],
                      consensus_mean=mean, consensus_sigma=sigma, iterations=self.iteration,
                      stop_reason=self.stop_reason or "not finished", timings=timings,
                      history=list(self.history), photometry=dict(self.photometry),
                      search=dict(self.search), layers=layers,
                      confidence=of_solver(self, disparity, foreground, occlusion))

    def close(self):
        """Free the solver's device memory (the object cannot be used afterwards)."""
        for grid in self._grids.values():
            grid.destroy()
        self.grid, self._grids = None, {}

    @property
    def memory_bytes(self):
        """Bytes held by the solver's fields, distance-transform scratch included."""
        return sum(grid.nbytes for grid in self._grids.values())

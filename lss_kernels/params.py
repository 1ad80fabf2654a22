"""Parameters of the method, validated once at the boundary: ``Params()``, the recommended
defaults, and ``Params.paper()``, the paper's method and nothing beyond it.

Section 4 of the paper: dt = 0.2, alpha = (0.2, 0.8, 0.1), mu = 4.0, beta = 0.4 / d_max, phi
re-initialised to a signed distance every 10 iterations and 7x7-median-filtered after every
step.  The remaining values are the choices of the authors' public release (patch sizes, filter
widths, thresholds); ``mono_threshold`` is one value for every scene where the release tuned it
per scene.  The defaults add what the paper does not have (``Params.paper`` lists it).
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass


def c_max(d_max) -> int:
    """The cyclopean search range for a left-view ``d_max``: candidates c = 1 ..
    ``ceil(d_max / 2)`` (the authors' disparities ``2 .. d_max``), at least 1.  A pair
    searched from 0 px holds one more (:mod:`lss_kernels.model.offset`)."""
    return max(1, int(math.ceil(float(d_max) / 2.0)))


# Constants of the authors' release that no scene needs changed: the scale of phi and the
# filters and clips of the Eq. 2 step (lss_kernels.model.levelset), and B_occ's detector
# (lss_kernels.model.costs); the refinement's peak-ratio and support thresholds
# (lss_kernels.model.refine).

#: The colour term's weight for a point's start (``Params.appearance`` None).
APPEARANCE = 0.06
#: phi is a signed distance (in pixels) times this factor (the release: 0.01).
PHI_SCALE = 0.01
#: Sigma (pixels) of the Gaussian-derivative filters for the curvature and the normal.
CURVATURE_SIGMA = 4.0
#: |kappa| is clipped to this.
CURVATURE_CLIP = 10.0
#: The boundary term B kappa + N . grad B is clipped to [-BOUNDARY_CLIP, BOUNDARY_CLIP].
BOUNDARY_CLIP = 1.0
#: Sigma (pixels) of the epipolar Gaussian derivative of the cost volume behind B_occ.
OCC_SIGMA = 3.0
#: Threshold on |dM/dx| that marks likely occlusion boundaries for B_occ.
OCC_THRESHOLD = 0.02
#: Peak-ratio threshold of a distinct match in the refinement (its cost below this times the
#: best candidate's that is not its neighbour).
REFINE_RATIO = 0.9
#: Fraction of a residual box's layer pixels that must hold a distinct match for its average
#: residual to count fully; below it the residual shrinks in proportion, so that a
#: textureless layer, whose few distinct matches are noise, keeps its quadratic.
REFINE_SUPPORT = 0.03


@dataclass(frozen=True)
class Params:
    """Every tunable of the solver.

    Attributes
    ----------
    dt : float
        Time step of the level-set descent (Eq. 2).
    alpha : (float, float, float)
        ``(alpha_1, alpha_2, alpha_3)`` of the boundary weight B = alpha_1 B_occ + alpha_2
        B_mono + alpha_3 (Eq. 1).
    mu : float
        Weight of the boundary-length term (Eq. 1, Eq. 2).
    beta : float
        Weight of |d - D| in the patch cost C_p (Eq. 5), as a multiple of 1 / c_max
        (the paper's beta = 0.4 / d_max with costs that are patch means in [0, 1]).
    patch_sizes : tuple of int
        Side of the square patches at each level of the hierarchy (the release: 3, 9, 18).
        Each size must be a multiple of the one below it (a patch is the union of
        non-overlapping children).
    reinit_every : int
        Re-initialise phi to a signed distance every this many iterations.
    median_size : int
        Side of the median filter applied to phi after every step (odd).
    max_iterations : int
        Iteration cap (the authors' release runs 1500 iterations; the paper gives no count).
    min_iterations : int
        The stopping rule is not consulted before this many iterations (three windows: the
        boundary has been re-initialised and the background swept a few times).
    stop_window : int
        The stopping rule looks at the foreground changes over this many iterations.
    stop_shift : float
        Every ``stop_window`` iterations, the pixels whose foreground label differs from
        ``stop_window`` iterations before are counted (an oscillating boundary does not
        count) and divided by the boundary's length in pixels: the boundary's mean shift
        over the window.  The window is quiet when that is below this many pixels.  The
        same test for a small object as for a large one (a fraction of the area, 0.2 %,
        would ask a disc of radius 30 px to settle to 0.03 px, one of 300 px to 0.3 px).
        0 disables the rule (run to ``max_iterations``).
    stop_surface : float
        A window is quiet only if, at each re-initialisation within it, neither layer's
        surface has moved by this many left-view pixels or more since the one before
        (measured on the layer's own pixels): a model still cycling under a settled
        boundary is not converged, unless no pixel changed its label over the window
        (surfaces cycling under a boundary that stands still: no wait ends such a cycle).
        0 leaves this test out.
    stop_patience : int
        Stop after this many consecutive quiet windows.  Windows before ``min_iterations``
        count towards it: the rule can fire at ``min_iterations``.  With the defaults paper15
        stops at a median of 140 iterations (``docs/design.md``, the stopping rule).
    narrow_band : float
        Eq. 2 moves phi only within this many pixels of the boundary (|phi| <=
        ``narrow_band * PHI_SCALE``); 0: everywhere, as the paper's delta_eps does, whose
        tail lets a weak, noisy data term open holes far inside a region
        (:mod:`lss_kernels.model.levelset`).  Half a pixel beyond a whole number: the
        re-initialised phi is ``PHI_SCALE`` times whole-pixel distances, which would sit on
        the band's edge.
    mono_threshold : float
        Threshold on the Sobel magnitude that marks image edges for B_mono (one value for
        every scene).
    matching_cost : {"ad", "ad_census"}
        The pixel matching cost M (:mod:`lss_kernels.model.matching`): "ad", the paper's
        absolute colour difference, or "ad_census", AD-Census (census of 7x7 grey windows
        beside the colour difference), which matches dark, low-contrast and radiometrically
        different views as sharply as bright ones.
    subpixel_messages : bool
        Eq. 5 takes d_p as an argmin over a continuous d: True refines the integer argmin to
        the vertex of the parabola through the patch cost at it and its two neighbours
        (within half a step).  False: the integer argmin of the authors' release (left-view
        disparities quantised to even values, which biases Theta by a fraction of a pixel
        and pulls the boundary inwards).
    refine : bool
        Refine each layer's disparity by a residual from its own matches
        (:mod:`lss_kernels.model.refine`, surface plus parallax); False keeps the paper's
        two quadratics (``Result.surface`` holds them either way).
    refine_passes : tuple of (range, window, smoothing)
        Per refinement pass: the candidate half-range around the layer's surface, the
        half-side of the layer-restricted matching window and of the residual's averaging
        box (left-view pixels).
    strip_window : (int, int)
        ``(near, far)``: after the refinement every occluded strip of the output is measured
        again, as the jump from the foreground at its edge to the background where the right
        camera sees it again, the background's quadratic there offset by the median of the
        refined minus the quadratic disparity over the background pixels ``near`` to ``far``
        left-view pixels beyond the strip
        (:meth:`~lss_kernels.model.occlusion.OcclusionGeometry.measure_strips`): one
        quadratic cannot follow a box, a shelf or a floor beside the object; ``far - near
        >= 2``, a window that can hold the three matched pixels a re-measure needs.
        ``(0, 0)``: the strips of the two quadratics, the paper's; so it is without
        ``refine``.
    message_ambiguity : float
        0: a patch's message weighs 1 / sigma_p^2 in the consensus (Eq. 7).  > 0: also times
        its cost curve's distinctness ``clip((1 - r) / message_ambiguity, 0, 1)``, ``r`` the
        peak ratio of the second-deepest minimum (:class:`~lss_kernels.model.messages.Messages`).
    recover : bool
        A model that collapsed (no foreground, no disparity jump, the foreground behind the
        background, or its surface outside ``[0, d_max]``) is solved again with the
        AD-Census cost and distinctness-weighted messages, and the second model kept when it
        is sound (:mod:`lss_kernels.checks.recovery`; :func:`~lss_kernels.solve`, ``lss
        solve``, ``lss batch`` and ``lss eval``; a bare ``Solver.run`` does not).
    photometric : bool
        Correct the right view to the left one's photometry (a gain, a radial vignetting and
        an offset fitted at the pair's matches) before the costs, where the views differ and
        that model explains the difference (:mod:`lss_kernels.checks.photometry`).
    background_sweep : float
        Margin of the background's plane sweep (:mod:`lss_kernels.model.sweep`): after the
        fit, in the first ``reinit_every`` iterations and at every re-initialisation,
        Theta_2 is reset to the fronto-parallel plane that minimises the visible
        background's mean standardised matching cost when that mean lies more than this
        below the fitted Theta_2's and the plane is a distinct dip of the sweep (a
        background too dark or too weakly textured for the consensus to place it); the
        next iterations fit Theta_2 again, from the consensus that the plane's D has
        shaped.  0: Theta_2 is always the Eq. 8 fit, as in the paper.
    zero_floor : bool
        Search a pair from 0 px when its first consensus puts at least 15 % of its confident
        pixels below 4 px (a far background), else from 2 px as the authors' grid does
        (:mod:`lss_kernels.model.offset`).  Any other pair is solved exactly as without it.
    front_margin : float
        A third layer in front of the object (:mod:`lss_kernels.model.front`): pixels whose
        first consensus stands more than this many left-view pixels in front of Theta_1, and
        the strips they hide, leave both fits and the Eq. 2 data term.  0: the paper's two
        layers.  On the rendered multi-object family it lowers the mean occlusion F1 (see
        ``docs/whole-photo.md``): off by default, also for a whole photo.
    local_background : int
        Radius, in tiles of 16 cyclopean pixels, of the local background
        (:meth:`~lss_kernels.model.shapes.GlobalShapes.fit_local`): Theta_2 read at a pixel
        is the blend of the quadratics fitted to the background around the nearby tiles,
        pulled towards the global fit where they hold little background.  0: the paper's
        one global quadratic.
    appearance : float or None
        Weight of the layers' colour term in Eq. 2 (:mod:`lss_kernels.model.appearance`):
        where the matches are uncertain, a pixel leans to the layer whose colours it has.
        None: ``APPEARANCE`` for a point's start (one object clicked among many, whose
        neighbours the colours tell apart), 0 for any other; the solver resolves it when it
        is built.  0: the paper's data term alone.
    """

    dt: float = 0.2
    alpha: tuple = (0.2, 0.8, 0.1)
    mu: float = 4.0
    beta: float = 0.4
    patch_sizes: tuple = (3, 9, 18)
    reinit_every: int = 10
    median_size: int = 7
    max_iterations: int = 1500
    min_iterations: int = 60
    stop_window: int = 20
    stop_shift: float = 0.1
    stop_surface: float = 1.0
    stop_patience: int = 1
    narrow_band: float = 10.5
    mono_threshold: float = 0.08
    matching_cost: str = "ad"
    subpixel_messages: bool = True
    refine: bool = True
    refine_passes: tuple = ((24, 7, 8), (4, 4, 2))
    strip_window: tuple = (6, 20)
    message_ambiguity: float = 0.0
    recover: bool = True
    photometric: bool = True
    zero_floor: bool = True
    background_sweep: float = 0.05
    refine_ellipse: bool = True
    front_margin: float = 0.0
    local_background: int = 0
    appearance: float | None = None

    def __post_init__(self):
        self.validate()

    def validate(self) -> None:
        """Raise ``ValueError`` naming the first parameter that is out of range."""
        def need(name, ok, expected):
            value = getattr(self, name)
            if isinstance(value, bool) or not ok(value):
                raise ValueError(f"params.{name}: expected {expected}, got {value!r}")

        def switch(name):
            value = getattr(self, name)
            if not isinstance(value, bool):
                raise ValueError(f"params.{name}: expected True or False, got {value!r}")

        finite = lambda v: isinstance(v, (int, float)) and math.isfinite(v)
        pos = lambda v: finite(v) and v > 0
        nonneg = lambda v: finite(v) and v >= 0
        posint = lambda v: isinstance(v, int) and v >= 1
        need("dt", lambda v: pos(v) and v <= 10, "a number in (0, 10]")
        need("alpha", lambda v: isinstance(v, tuple) and len(v) == 3 and all(
            nonneg(a) and not isinstance(a, bool) for a in v),
            "a tuple of three finite numbers >= 0")
        need("mu", nonneg, "a finite number >= 0")
        need("beta", nonneg, "a finite number >= 0")
        need("background_sweep", nonneg, "a finite number >= 0")
        need("patch_sizes", lambda v: isinstance(v, tuple) and len(v) >= 1
             and all(isinstance(s, int) and not isinstance(s, bool) and s >= 2 for s in v)
             and all(b % a == 0 and b > a for a, b in zip(v, v[1:])),
             "a tuple of increasing integers >= 2, each a multiple of the one before")
        need("reinit_every", posint, "an integer >= 1")
        need("median_size", lambda v: isinstance(v, int) and v in (1, 3, 5, 7),
             "1, 3, 5 or 7")
        need("max_iterations", posint, "an integer >= 1")
        need("min_iterations", lambda v: isinstance(v, int) and v >= 0, "an integer >= 0")
        need("stop_window", posint, "an integer >= 1")
        need("stop_shift", nonneg, "a finite number of pixels >= 0 (0: no stopping rule)")
        need("stop_surface", nonneg, "a finite number of pixels >= 0 (0: no surface test)")
        need("stop_patience", posint, "an integer >= 1")
        need("narrow_band", nonneg, "a finite number of pixels >= 0 (0: no band)")
        need("mono_threshold", pos, "a finite number > 0")
        need("matching_cost", lambda v: v in ("ad", "ad_census"), "'ad' or 'ad_census'")
        for name in ("subpixel_messages", "zero_floor", "refine_ellipse", "refine"):
            switch(name)
        need("refine_passes", lambda v: isinstance(v, tuple) and len(v) >= 1 and all(
            isinstance(p, tuple) and len(p) == 3 and all(
                isinstance(k, int) and not isinstance(k, bool) and 1 <= k <= 64 for k in p)
            for p in v), "a tuple of (range, window, smoothing) triples of integers in "
            "[1, 64]")
        need("strip_window", lambda v: v == (0, 0) or (
            isinstance(v, tuple) and len(v) == 2
            and all(isinstance(k, int) and not isinstance(k, bool) for k in v)
            and 0 <= v[0] and v[0] + 2 <= v[1] <= 64),
            "(0, 0) or (near, far), integers with 0 <= near, near + 2 <= far <= 64")
        need("message_ambiguity", lambda v: finite(v) and 0 <= v <= 1,
             "a number in [0, 1] (0: off)")
        switch("recover")
        switch("photometric")
        need("front_margin", nonneg, "a finite number of pixels >= 0 (0: two layers)")
        need("local_background", lambda v: isinstance(v, int) and not isinstance(v, bool)
             and 0 <= v <= 8, "an integer in [0, 8] (0: one global Theta_2)")
        need("appearance", lambda v: v is None or nonneg(v),
             "None (a point's start: APPEARANCE; any other: 0) or a finite weight >= 0 "
             "(0: no colour term)")

    @classmethod
    def paper(cls, **changes) -> "Params":
        """The paper's method as the authors' release runs it, and nothing beyond it: the
        absolute-difference cost, Eq. 2's step everywhere (no narrow band), the integer
        argmin of Eq. 5, Theta_2 by the Eq. 8 fit alone (no plane sweep), the start ellipse
        as drawn, the two quadratics as the output (no refinement, the z-buffer's strips),
        no photometric correction, no recovery solve, the release's grid from 2 px.  Theta's
        rows are weighted as the release does (``model.shapes.WEIGHT_POWER``).  The stopping
        rule stands for the paper's "upon convergence" (the release runs ``max_iterations``,
        1500).  ``changes`` as for :meth:`replace`."""
        return cls().replace(**{
            "matching_cost": "ad", "narrow_band": 0.0, "subpixel_messages": False,
            "background_sweep": 0.0, "refine_ellipse": False, "refine": False,
            "strip_window": (0, 0), "photometric": False, "recover": False,
            "zero_floor": False, "message_ambiguity": 0.0, "appearance": 0.0, **changes})

    def for_start(self, init) -> "Params":
        """These parameters with ``appearance`` resolved for the start ``init``: None is
        ``APPEARANCE`` for a :class:`~lss_kernels.Point`, 0 for any other start."""
        if self.appearance is not None:
            return self
        from .start_types import Point
        return self.replace(appearance=APPEARANCE if isinstance(init, Point) else 0.0)

    def replace(self, **changes) -> "Params":
        """A copy with some fields changed (validated)."""
        unknown = set(changes) - {f.name for f in dataclasses.fields(self)}
        if unknown:
            raise ValueError(f"params: unknown parameter(s) {sorted(unknown)}")
        return dataclasses.replace(self, **changes)

    def to_dict(self) -> dict:
        d = dataclasses.asdict(self)
        d["alpha"] = list(self.alpha)
        d["patch_sizes"] = list(self.patch_sizes)
        d["refine_passes"] = [list(p) for p in self.refine_passes]
        d["strip_window"] = list(self.strip_window)
        return d

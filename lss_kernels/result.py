"""What a solve returns: :class:`Result`."""
from dataclasses import dataclass, field

import numpy as np

__all__ = ["Result"]


@dataclass
class Result:
    """Output of :func:`solve`.

    Left view (the user's frame, Middlebury convention): ``disparity`` ``(H, W)`` float32 in
    left-view pixels (finite, clamped to ``[0, d_max]``): each layer's surface refined by its
    own matches (surface plus parallax, :mod:`lss_kernels.model.refine`; the surface itself
    with ``Params(refine=False)``); ``surface``: the two quadratics' disparity (the paper's
    model); ``occlusion`` (seen by the left camera, hidden from the right) and
    ``foreground`` boolean ``(H, W)``; ``confidence`` float32 ``(H, W)`` in [0, 1], how sure
    each pixel's disparity is (:mod:`lss_kernels.confidence`; 0 on occluded pixels).
    :meth:`depth` and :meth:`points` give metric depth and 3-D points for a calibration.

    Cyclopean frame (the model's): ``phi`` ``(H, W)`` (> 0 foreground), ``consensus_mean`` and
    ``consensus_sigma`` ``(H, W)`` in left-view disparity units (sigma = d_max where no valid
    patch covers the pixel).  ``theta_fg``, ``theta_bg``: coefficients of the left-view
    disparity (2 Theta_j) over the basis {x^2, xy, y^2, x, y, 1} of raw cyclopean pixel
    coordinates.  ``iterations`` run, ``stop_reason``, ``timings`` (seconds per stage) and
    ``history`` (per-iteration statistics); ``recovery``: whether the model collapsed and
    was solved again (:mod:`lss_kernels.checks.recovery`; set by :func:`solve`, not by
    ``run``); ``photometry``: the right view's photometric correction
    (:mod:`lss_kernels.checks.photometry`);
    ``search``: where the disparity grid started, 2 or 0 px (:mod:`lss_kernels.model.offset`).
    ``layers``: uint8 ``(H, W)``, left view: 0 background, 1 the object (``foreground``), 2 in
    front of it (:mod:`lss_kernels.model.layers`; only with ``Params.front_margin``).
    ``window``: ``(x0, y0, x1, y1)``, the part of a whole photo that was solved
    (:mod:`lss_kernels.photo`; None: the whole pair).
    """

    disparity: np.ndarray
    surface: np.ndarray
    occlusion: np.ndarray
    foreground: np.ndarray
    confidence: np.ndarray
    phi: np.ndarray
    theta_fg: np.ndarray
    theta_bg: np.ndarray
    consensus_mean: np.ndarray
    consensus_sigma: np.ndarray
    iterations: int
    stop_reason: str
    timings: dict = field(default_factory=dict)
    history: list = field(default_factory=list)
    recovery: dict = field(default_factory=dict)
    photometry: dict = field(default_factory=dict)
    search: dict = field(default_factory=dict)
    layers: np.ndarray | None = None
    window: tuple | None = None

    def depth(self, calib):
        """Left-view depth ``focal * baseline / (disparity + doffs)`` (float32 ``(H, W)``, the
        baseline's unit; inf where unknown) for a :class:`~lss_kernels.calib.Calibration`."""
        return calib.depth(self.disparity)

    def points(self, calib, which="object", min_confidence=0.0):
        """3-D points (float32 ``(N, 3)``, left camera frame: x right, y down, z forward)
        of ``which`` pixels (:func:`lss_kernels.cloud.select`: ``"object"``, ``"all"`` seen
        by both cameras, ``"background"``) whose :attr:`confidence` is at least
        ``min_confidence``, in row-major pixel order; pixels at infinite depth give none."""
        from .cloud import select
        mask = select(which, self.foreground, self.occlusion, self.confidence, min_confidence)
        return calib.points(self.disparity, mask)[0]

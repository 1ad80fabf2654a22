"""A rectified pair checked once, at the boundary, with what the checks found in it.

:class:`CheckedPair` reads and validates the inputs of a solve once
(:func:`~lss_kernels.checks.validate.check_inputs`) and holds their grey images
(:func:`~lss_kernels.checks.validate.luma`).  What the checks measure on it is computed
from those grey images the first time it is asked for, and kept: the left image's
periodicity (:mod:`.periodicity`), the photometric model of the right view on the left one
(:mod:`.photometry`), and the direction and range of the matches (:mod:`.direction`).
Nothing downstream reads, checks or turns the pair to grey again: the solves of a recovery
and the solver's start all ask the one pair.
"""
from functools import cached_property

from . import direction, photometry
from .periodicity import PERIODIC_AREA, periodic_tiles, periodicity
from .validate import check_inputs, check_params, luma

__all__ = ["CheckedPair"]


class CheckedPair:
    """The inputs of a solve, checked.

    Parameters
    ----------
    left, right, d_max, init, init_frame
        As for :class:`~lss_kernels.Solver`.
    params : Params, optional
        The parameters whose patch sizes bound the image's size (None: the defaults).

    Attributes
    ----------
    left, right : ndarray float32 ``(H, W, 3)`` in [0, 1]
        The images as the solver reads them (a grey view beside a colour one made grey).
    grey : (ndarray, ndarray) float64 ``(H, W)``
        Their luma.
    d_max : float
    init : tuple of 4 float, ndarray bool ``(H, W)``, ``"auto"``, Point or Box
    init_frame : {"left", "cyclopean"}
    """

    def __init__(self, left, right, d_max, init, init_frame, params):
        self.left, self.right, self.d_max, self.init = check_inputs(
            left, right, d_max, init, init_frame, check_params(params))
        self.init_frame = init_frame
        self.grey = luma(self.left), luma(self.right)

    @classmethod
    def of(cls, left, right, d_max, init, init_frame, params):
        """``left`` itself when it is a checked pair, else the pair of the arguments."""
        if isinstance(left, cls):
            return left
        return cls(left, right, d_max, init, init_frame, params)

    @cached_property
    def periodicity(self):
        """The left image's :func:`~lss_kernels.checks.periodicity.periodicity` per tile."""
        return periodicity(self.grey[0])

    @cached_property
    def periodic(self) -> float:
        """The fraction of the left image's tiles that are periodic."""
        return periodic_tiles(self.periodicity)

    @property
    def periodic_share(self) -> float:
        """:attr:`periodic` where it reaches ``PERIODIC_AREA`` (the image counts as
        periodic), else 0 (what a start from the first consensus is told)."""
        return self.periodic if self.periodic >= PERIODIC_AREA else 0.0

    @cached_property
    def photometry(self) -> dict:
        """:func:`~lss_kernels.checks.photometry.fit` of the right view on the left one."""
        return photometry.fit(*self.grey, self.d_max)

    def right_view(self, correct: bool):
        """``(right, facts)``: with ``correct`` (``Params.photometric``), the right image
        corrected where :attr:`photometry` says so, and its facts; else the right image as
        given."""
        if not correct:
            return self.right, {"correct": False, "why": "Params.photometric is False"}
        return self._corrected, self.photometry

    @cached_property
    def _corrected(self):
        return photometry.corrected(self.right, self.photometry)

    @cached_property
    def direction(self) -> dict:
        """:func:`~lss_kernels.checks.direction.match_direction` of the pair."""
        return direction.match_direction(*self.grey, self.d_max)

    @cached_property
    def range(self) -> dict:
        """:func:`~lss_kernels.checks.direction.match_range` of the pair."""
        return direction.match_range(*self.grey, self.d_max)

"""What a solve can start from, besides an ellipse or a mask: ``AUTO``, a :class:`Point` or a
:class:`Box` (left-view pixels, 0-based, x to the right, y down), and the error raised when no
foreground is found from them, or the warning that it may be the wrong one.  No
dependencies: the model finds the region (:mod:`lss_kernels.model.init`), the input checks
read the types (:mod:`lss_kernels.checks.validate`).
"""
from dataclasses import dataclass

__all__ = ["AUTO", "Box", "InitError", "Point", "UnreliableStartWarning"]

#: Find the object without any hint (:class:`~lss_kernels.model.init.InitialRegion`).
AUTO = "auto"


class InitError(ValueError):
    """No foreground could be found from the given initialisation."""


class UnreliableStartWarning(UserWarning):
    """``init="auto"`` found its start on a periodic left image, whose first consensus the
    stripes make ambiguous: the start, and so the answer, may be the wrong region
    (:mod:`lss_kernels.model.init`)."""


@dataclass(frozen=True)
class Point:
    """A left-view pixel on the object (a click): ``x`` to the right, ``y`` down, 0-based."""
    x: float
    y: float


@dataclass(frozen=True)
class Box:
    """A left-view box around the object (a detector's output): corners ``(x0, y0)`` and
    ``(x1, y1)``, 0-based pixels, ``x0 < x1``, ``y0 < y1``."""
    x0: float
    y0: float
    x1: float
    y1: float

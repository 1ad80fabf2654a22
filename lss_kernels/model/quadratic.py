"""The paper's quadratic surfaces on the host (numpy): Theta . U(x, y) with the basis
U = {x^2, xy, y^2, x, y, 1} of Eq. 8, in whatever coordinates the coefficients are given
(normalised, cyclopean or left-view pixels).  The kernels' own evaluation is
:func:`lss_kernels.kernels.curves.quadratic`."""
import numpy as np

__all__ = ["basis", "evaluate"]


def basis(x, y):
    """U(x, y) along a new last axis."""
    x, y = np.asarray(x, np.float64), np.asarray(y, np.float64)
    return np.stack([x * x, x * y, y * y, x, y, np.ones_like(x)], axis=-1)


def evaluate(theta, x, y):
    """Theta . U(x, y) at every (x, y), broadcast."""
    t = np.asarray(theta, np.float64)
    return t[0] * x * x + t[1] * x * y + t[2] * y * y + t[3] * x + t[4] * y + t[5]

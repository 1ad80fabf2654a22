"""Readable numpy specification of the background's plane sweep
(:mod:`lss_kernels.model.sweep`), in float64; frames and units as in
:mod:`lss_kernels.reference.kernels`.  The sums are specified here; the choice among them is
the model's own :func:`~lss_kernels.model.sweep.choose_plane` (a host function)."""
import numpy as np

from ..model.sweep import FLAT, NEAR, choose_plane
from .kernels import interp_volume

__all__ = ["background_sweep", "sweep_totals"]


def sweep_totals(cost, visible, theta1, theta2, consensus):
    """Over the ``visible`` pixels whose ``consensus`` lies at least ``NEAR`` from ``theta1``
    (maps ``(H, W)``): each pixel's standardised cost curve ``(M(c) - mean_c M) / std_c M``
    (0 for a curve of spread at most ``FLAT``) summed at every candidate c, summed at
    ``theta2`` (linear in c, clamped to ``[1, c_max]``), and the pixels' count."""
    sd = cost.std(axis=2, keepdims=True)
    z = np.where(sd > FLAT, (cost - cost.mean(axis=2, keepdims=True)) / np.maximum(sd, FLAT),
                 0.0)
    sel = visible & (np.abs(consensus - theta1) >= NEAR)
    x = np.broadcast_to(np.arange(cost.shape[1], dtype=np.float64), sel.shape)
    at_theta2 = interp_volume(z, x, theta2)
    return np.concatenate([z[sel].sum(axis=0), [at_theta2[sel].sum(), sel.sum()]])


def background_sweep(cost, visible, theta1, theta2, consensus, margin):
    """The plane the sweep sets (cyclopean disparity), or None: :func:`sweep_totals` through
    :func:`~lss_kernels.model.sweep.choose_plane`."""
    return choose_plane(sweep_totals(cost, visible, theta1, theta2, consensus), margin,
                        visible.size)

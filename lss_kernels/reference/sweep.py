"""Readable numpy specification of the background's plane sweep
(:mod:`lss_kernels.model.sweep`), in float64; frames and units as in
:mod:`lss_kernels.reference.kernels`."""
import numpy as np

from ..model.sweep import FLAT, MIN_SHARE, NEAR, distinct_dip, plane_vertex

__all__ = ["background_sweep"]


def background_sweep(cost, visible, theta1, theta2, consensus, margin):
    """The background's plane sweep (:mod:`lss_kernels.model.sweep`): over the ``visible``
    pixels whose ``consensus`` lies at least ``NEAR`` from ``theta1`` (maps ``(H, W)``), the
    mean of each pixel's standardised cost curve ``(M(c) - mean_c M) / std_c M`` (0 for a
    curve of spread at most ``FLAT``) at every candidate c and at ``theta2`` (linear in c, clamped to
    ``[1, c_max]``).  Returns the best candidate's vertex (cyclopean) when its mean lies more
    than ``margin`` below ``theta2``'s and it is a distinct dip (``distinct_dip``), with at
    least ``MIN_SHARE`` of the pixels swept; else None."""
    C = cost.shape[2]
    sd = cost.std(axis=2, keepdims=True)
    z = (cost - cost.mean(axis=2, keepdims=True)) * np.where(sd > FLAT, 1.0 / np.where(
        sd > FLAT, sd, 1.0), 0.0)
    sel = visible & (np.abs(consensus - theta1) >= NEAR)
    if sel.sum() < max(1.0, MIN_SHARE * sel.size):
        return None
    zs = z[sel]
    kf = np.clip(theta2[sel] - 1.0, 0.0, C - 1.0)
    k0 = np.clip(np.floor(kf).astype(int), 0, max(C - 2, 0))
    k1 = np.minimum(k0 + 1, C - 1)
    rows = np.arange(len(zs))
    at_theta2 = ((1.0 - (kf - k0)) * zs[rows, k0] + (kf - k0) * zs[rows, k1]).mean()
    mean = zs.mean(axis=0)
    k = int(np.argmin(mean))
    return (plane_vertex(mean, k) if mean[k] < at_theta2 - margin and distinct_dip(mean, k)
            else None)

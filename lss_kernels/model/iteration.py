"""The stages of one iteration that always run one after the other, as one kernel each.

:meth:`lss_kernels.Solver.step` runs the stages of Sec. 3 in order; a ``@ti.kernel`` with
several top-level loops runs them in order too, so stages with nothing on the host between
them are one launch and one compiled kernel, composed from the stages' own ``ti.func`` (each
stage keeps its kernel, which the tests and ``Solver(profile=True)``'s per-stage timings
use).  The kernels belong to one disparity grid's stage objects, like the stages' own.
"""
import taichi as ti

__all__ = ["IterationKernels"]


@ti.data_oriented
class IterationKernels:
    """The fused stages of an iteration for one grid's ``levelset``, ``occ``, ``hierarchy``,
    ``messages``, ``shapes`` and ``costs``."""

    def __init__(self, levelset, occ, hierarchy, messages, shapes, costs):
        self.levelset, self.occ, self.hierarchy = levelset, occ, hierarchy
        self.messages, self.shapes, self.costs = messages, shapes, costs

    @ti.kernel
    def derivatives(self, band: ti.f32):
        """phi's derivatives (:meth:`~lss_kernels.model.levelset.LevelSet.derivatives`),
        then phi(x + delta_theta) (:meth:`~lss_kernels.model.occlusion.OcclusionGeometry.
        refresh_phi_plus`)."""
        self.levelset.derive(band)
        self.occ.refresh(self.levelset.phi)

    @ti.kernel
    def consensus(self, beta: ti.f32, use_validity: ti.i32):
        """The messages (Eqs. 4, 5; :meth:`~lss_kernels.model.messages.Messages.run`, whose
        ``prepare`` ran on the host) and the consensus (Eq. 7; :meth:`~lss_kernels.model.
        hierarchy.PatchHierarchy.downward`)."""
        self.messages.levels_func(beta, use_validity, False)
        self.hierarchy.down()

    @ti.kernel
    def geometry(self, ray_cast: ti.i32, t_max: ti.f32):
        """delta_theta for the new Theta (:meth:`~lss_kernels.model.occlusion.
        OcclusionGeometry.compute`), then B and its gradient's row pass
        (:meth:`~lss_kernels.model.levelset.LevelSet.boundary_weight`)."""
        self.occ.cast(self.shapes, self.levelset.phi_x, ray_cast, t_max)
        self.levelset.boundary_terms(self.costs, self.shapes)

"""One disparity grid of a solve: the fields of ``c_max`` cyclopean candidates and the stage
objects that own them, in a pool of their own.

A :class:`~lss_kernels.Solver` holds the authors' grid (``c = 1 .. ceil(d_max / 2)``) and,
once a pair was searched from 0 px, the grid of one plane more (:mod:`.offset`); it switches
between them as a whole (``Solver.grid``).
"""
import taichi as ti

from ..kernels.backend import FieldPool
from .appearance import Appearance
from .costs import BoundaryCosts
from .front import FrontLayer
from .hierarchy import PatchHierarchy
from .init import InitialRegion
from .iteration import IterationKernels
from .levelset import LevelSet
from .matching import MatchingCost
from .messages import Messages
from .occlusion import OcclusionGeometry
from .refine import LayerRefinement
from .shapes import GlobalShapes, RegionWeights
from .sweep import BackgroundSweep

__all__ = ["BRIDGE_GAP", "Grid"]

#: Widest layer in front of the object that a point's start is carried across (a rod, a
#: handle), cyclopean pixels (:meth:`lss_kernels.model.init.InitialRegion.bridge`).
BRIDGE_GAP = 16


class Grid:
    """The fields and kernels of a solve of ``height x width`` with ``c_max`` cyclopean
    candidates, in a new :class:`~lss_kernels.kernels.backend.FieldPool` (zero, finalised).

    Attributes: ``c_max``, ``pool``, ``extent``, the model's pair ``left``, ``right``, and
    the stages ``matching``, ``hierarchy``, ``messages``, ``costs``, ``initialiser``,
    ``occ``, ``levelset``, ``front`` (None without ``params.front_margin``), ``appearance``
    (None without ``params.appearance``), ``shapes``,
    ``refinement`` (None without ``params.refine``) and ``fused``.  Their fields have the
    shape of the image's size bucket and the kernels read H and W at run time: they compile
    once per bucket.
    """

    def __init__(self, height, width, c_max, params):
        H, W, C = int(height), int(width), int(c_max)
        p = params
        self.c_max = C
        self.pool = pool = FieldPool()
        self.extent = pool.extent(H, W)
        self.left = pool.vector(3, ti.f32, self.extent.bucket, bucket=True)
        self.right = pool.vector(3, ti.f32, self.extent.bucket, bucket=True)
        self.matching = MatchingCost(pool, H, W, p.matching_cost)
        self.hierarchy = h = PatchHierarchy(pool, H, W, C, p.patch_sizes)
        self.messages = Messages(h, p.subpixel_messages, pool, p.message_ambiguity)
        self.costs = BoundaryCosts(pool, H, W, C)
        self.initialiser = InitialRegion(pool, H, W)
        self.occ = OcclusionGeometry(pool, H, W, C)
        self.levelset = LevelSet(pool, H, W, p)
        self.front = FrontLayer(pool, H, W) if p.front_margin > 0 else None
        self.appearance = Appearance(pool, H, W) if p.appearance else None
        if self.front is not None:
            self.levelset.hidden = self.front.hidden
            self.initialiser.bridge_gap = BRIDGE_GAP
        weights = RegionWeights(self.extent, h.precision, h.consensus_mean, self.levelset.phi,
                                self.occ.phi_plus,
                                None if self.front is None else self.front.hidden)
        self.shapes = GlobalShapes(pool, H, W, weights, BackgroundSweep(pool, H, W, C),
                                   p.local_background)
        self.refinement = (LayerRefinement(pool.annex(), H, W, p.refine_passes)
                           if p.refine else None)
        # what the host reads and writes of the pool (FieldPool.host)
        pool.host(self.left, self.right, h.consensus_mean, h.precision,
                  self.occ.disparity_left, self.occ.occlusion_left, self.occ.foreground_left)
        if self.refinement is not None:
            r = self.refinement
            pool.host(r.surface, r.match, r.peak_ratio, r.weight)
        if self.front is not None:
            pool.host(self.front.front, self.front.first)
        self.fused = IterationKernels(self.levelset, self.occ, h, self.messages, self.shapes,
                                      self.costs)
        pool.finalize()
        self.levelset.setup()
        self.costs.setup(self.levelset.distance, self.levelset.distance_map)

    @property
    def nbytes(self):
        """Bytes held by the grid's fields, distance-transform scratch included."""
        return self.pool.nbytes + self.levelset.scratch_bytes + self.costs.scratch_bytes

    def destroy(self):
        """Free the grid's device memory."""
        self.levelset.destroy()
        self.costs.destroy()
        self.pool.destroy()

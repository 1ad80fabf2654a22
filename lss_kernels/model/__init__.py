"""The paper's model as data-parallel kernels, one module per concept.

=================  =========================================================================
``costs``          boundary costs B_occ, B_mono and their combination B (Sec. 4, Eq. 1)
``hierarchy``      the cooperative patch levels: matching costs per patch, the upward relays
                   and the downward consensus (Sec. 3, Eq. 7)
``patches``        the geometry of the hierarchy's levels: children, margins, relay columns
``messages``       per-patch validity and disparity messages (Eqs. 4, 5)
``shapes``         the quadratic surfaces Theta_1, Theta_2 by a hierarchical reduction of the
                   normal equations (Eq. 8)
``sweep``          the background's plane sweep: Theta_2 placed by the background's own
                   cost where Eq. 8's fit cannot place it
``occlusion``      delta_theta by the ray cast in x-d space, the visible background, the
                   left-view rendering (Sec. 2)
``levelset``       phi, its descent step (Eq. 2), re-initialisation and D (Eq. 3)
``iteration``      the stages of an iteration that run back to back, one kernel each
``grid``           one disparity grid: a pool of fields and the stage objects above
=================  =========================================================================

Nothing here imports :mod:`lss_kernels.apps`; the building blocks come from
:mod:`lss_kernels.kernels`.
"""

#: The stages of one iteration of the alternation, in order (the solver's timings, the numpy
#: specification and the benchmark use these names).
STAGES = ("upward", "messages", "downward", "shapes", "occlusion", "boundary", "levelset")

#: Fixed-point steps of the ray cast (:mod:`.occlusion`); the numpy specification takes the
#: same number.
FIXED_POINT_STEPS = 6

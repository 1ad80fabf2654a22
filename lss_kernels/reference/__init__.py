"""The numpy specifications the tests hold the kernels to: :mod:`.kernels` (one function per
kernel of the alternation), :mod:`.sweep` (the background's plane sweep), :mod:`.iteration`
(one whole iteration of the solver, composed of them) and :mod:`.refine` (the steps after the
alternation).  Slow, plain, float64; the solver never calls them."""

"""The numpy specifications the tests hold the kernels to: :mod:`.kernels` (one function per
kernel), :mod:`.sweep` (the background's plane sweep) and :mod:`.iteration` (one whole
iteration of the solver, composed of them).  Slow, plain, float64; the solver never calls
them."""

"""Taichi building blocks that know nothing of the paper.

=================  =========================================================================
``backend``        the one ``ti.init`` (arch probing, threads, offline cache) and FieldPool
``taichi_patches`` memoised pure computations of Taichi's front end (switchable)
``lanes``          lane planes: blocks of pixels per field element, for SIMD on the CPU
``filters``        separable Gaussian-derivative filters with symmetric borders
``median``         the median filter by shared-column selection networks
``distance``       exact Euclidean distance transforms
``curves``         a parabola's vertex, a curve's two minima, a quadratic in two variables
=================  =========================================================================
"""

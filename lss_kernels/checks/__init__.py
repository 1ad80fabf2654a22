"""The checks around a solve, one layer that wraps the :class:`~lss_kernels.Solver`; the model
(``model/``) never reaches up into it.

- :mod:`.validate`: the inputs read and checked at the boundary, one-line errors; the grey
  of the checks (:func:`~.validate.luma`);
- :mod:`.pair`: :class:`~.pair.CheckedPair`, a pair checked once with what the checks found;
- :mod:`.periodicity`: periodic texture along the rows;
- :mod:`.photometry`: the photometric difference between the views, and its correction;
- :mod:`.direction`: swapped views, a search range too short, a range for a pair given none;
- :mod:`.teeth`: on a periodic pair, the foreground moved to the tooth the outline shows;
- :mod:`.recovery`: a collapsed model recognised and solved again;
- :mod:`.split`: after a whole photo's solve, a neighbour just behind the object split off;
- :mod:`.around`: :func:`~lss_kernels.solve`, these checks around a solver.
"""

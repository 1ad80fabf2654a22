"""What users run: the ``lss`` command line (:mod:`.cli`) and its sub-commands (:mod:`.demo`,
:mod:`.evaluate`, :mod:`.bench`), and the OpenCV peers (:mod:`.baselines`).  Nothing in the
library imports this package."""

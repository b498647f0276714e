"""The test suite.

OpenBLAS gets one thread in every test process, set here because pytest imports this package before the
conftest's ``import numpy`` (OpenBLAS reads the variable once, when NumPy loads it; the processes the tests start
inherit it).  The suite already runs one worker process per core; a matrix product of a million directions by a
3 x 3 frame (``analysis/chi2.py``'s angles, the samplers' frames) then asked for a second BLAS thread on a core
that another worker held, and OpenBLAS's threads wait by spinning: 0.36-0.41 s a product instead of 8 ms with one
thread (decisions.md 133).  One thread computes the same numbers.
"""

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

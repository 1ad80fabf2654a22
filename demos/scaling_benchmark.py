"""Scaling benchmark of the solver stages (a thin wrapper of ``lss bench``).

    python demos/scaling_benchmark.py --quick --json
    python demos/scaling_benchmark.py --out docs/bench --threads 2 1
"""
import sys

from lss_kernels.bench import main

if __name__ == "__main__":
    sys.exit(main())

"""Scaling benchmark of the solver stages (a thin wrapper of ``lss bench``).

    python demos/scaling_benchmark.py --quick --json
    python demos/scaling_benchmark.py --out bench_out --threads 2 1
"""
import os
import sys

if "--json" in sys.argv:
    # keep stdout to the one JSON object: no Taichi banner on import
    os.environ.setdefault("ENABLE_TAICHI_HEADER_PRINT", "0")

from lss_kernels.apps.bench import main  # noqa: E402

if __name__ == "__main__":
    sys.exit(main())

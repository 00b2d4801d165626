"""Step cost of the co-simulation: the same as ``pmsm-cosim bench`` (see orchestrator/pmsm_cosim/app/bench.py).

    python benchmarks/step_cost.py [--slice S] [--no-memory] [--no-libcosim]
"""

import sys

from pmsm_cosim.app.bench import main

if __name__ == "__main__":
    sys.exit(main())

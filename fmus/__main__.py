"""``python -m pmsm_ev_fmus``: build the FMUs."""

import sys

from .build import main

sys.exit(main())

import sys
from pathlib import Path

# let tests import helper modules that live beside them (regression_runs)
sys.path.insert(0, str(Path(__file__).parent))

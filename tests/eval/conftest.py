import sys
from pathlib import Path

# Lets the tests import the plain reference implementation kept beside them.
sys.path.insert(0, str(Path(__file__).parent))

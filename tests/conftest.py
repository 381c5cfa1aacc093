import sys
from pathlib import Path

# tests import their shared helpers (compare_helpers) by module name
sys.path.insert(0, str(Path(__file__).parent))

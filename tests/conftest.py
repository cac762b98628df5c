import os
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))
# OpenMDAO writes an HTML report folder per problem into the working directory unless told not to
os.environ.setdefault("OPENMDAO_REPORTS", "0")
ROOT = Path(__file__).resolve().parent.parent
CASES = ROOT / "cases"

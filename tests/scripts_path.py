"""Import the case generators from scripts/ in tests."""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "scripts"))
from make_cases import duffing_chain, truss_impact  # noqa: E402,F401

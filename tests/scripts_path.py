"""Import the case generators from scripts/ in tests."""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "scripts"))
from make_cases import duffing_chain, truss_impact  # noqa: E402,F401
from extreme_cases import exact_two_dof, hard_step_case, sdof_in_units, two_dof  # noqa: E402,F401
from make_ground_structure import ground_structure, two_load_cases  # noqa: E402,F401

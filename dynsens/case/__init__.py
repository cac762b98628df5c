"""Case files: YAML -> validated :class:`~dynsens.case.load.Case`."""
from .load import Case, DesignVariable, load_case, load_case_dict

__all__ = ["Case", "DesignVariable", "load_case", "load_case_dict"]

"""Build hook: the example cases (the top-level ``cases/`` folder) ship in the wheel as the package
data folder ``dynsens/example_cases/``, which ``dynsens examples DIR`` copies.  Everything else is
configured in pyproject.toml."""
import shutil
from pathlib import Path

from setuptools import setup
from setuptools.command.build_py import build_py

CASES = Path(__file__).resolve().parent / "cases"


class BuildWithExampleCases(build_py):
    """build_py, then copy cases/ into the built package (an editable install reads cases/ in place)."""

    def run(self) -> None:
        super().run()
        if getattr(self, "editable_mode", False):
            return
        target = Path(self.build_lib) / "dynsens" / "example_cases"
        if target.exists():
            shutil.rmtree(target)
        shutil.copytree(CASES, target, ignore=shutil.ignore_patterns("__pycache__", "*.h5"))


setup(cmdclass={"build_py": BuildWithExampleCases})

"""The package list, found rather than typed: every folder with an ``__init__.py`` under each of the three
import packages' roots (pyproject.toml says why they live in three folders). Everything else about the
distribution is in pyproject.toml."""

from pathlib import Path

from setuptools import find_packages, setup

# import package -> its folder (also pyproject.toml's [tool.setuptools] package-dir)
ROOTS = {"pmsm_ev": "src/pmsm_ev", "pmsm_cosim": "orchestrator/pmsm_cosim", "pmsm_ev_fmus": "fmus"}


def found_packages(here: Path = Path(__file__).parent) -> list[str]:
    """Each root and each of its subpackages, by name (``pmsm_cosim.app.metrics``, ...)."""
    return sorted(name for root, folder in ROOTS.items()
                  for name in [root] + [f"{root}.{sub}" for sub in find_packages(str(here / folder))])


if __name__ == "__main__":
    setup(packages=found_packages(), package_dir=ROOTS)

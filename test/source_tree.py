"""A copy of the checkout as a user would make it (a tarball, ``cp -r``): without .git, virtual
environments, build output and git-ignored files. For the build tests (colcon, the wheel)."""

from __future__ import annotations

import shutil
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
# Never part of a source copy, whatever .gitignore says: version control, virtual
# environments, and the output of colcon, setuptools, pytest, ruff and mypy.
NOT_SOURCE = {".git", ".venv", "venv", "build", "install", "log", "__pycache__", ".pytest_cache", ".mypy_cache",
              ".ruff_cache", "*.egg-info", "*.pyc"}


def copy_source(dest: Path) -> None:
    """Copy the checkout to ``dest``, without .git and ignored files."""
    ignored = set(NOT_SOURCE)
    gitignore = ROOT / ".gitignore"
    if gitignore.is_file():
        for raw in gitignore.read_text().splitlines():
            pattern = raw.strip()
            if pattern and not pattern.startswith(("#", "!")):
                ignored.add(pattern.strip("/"))
    shutil.copytree(ROOT, dest, ignore=shutil.ignore_patterns(*ignored), symlinks=True)

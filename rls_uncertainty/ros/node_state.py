"""The node's estimator state file: claimed at start, resumed from when it holds this
configuration's state, set aside when it cannot be used, saved periodically and at shutdown.

What happens is said once in the node's log and kept as :attr:`NodeStateFile.status` for
``/diagnostics``; the file's I/O itself is :mod:`rls_uncertainty.state_file`'s.
"""

from __future__ import annotations

import os
from typing import Any

from ..datapath.pipeline import Pipeline, StateFileError
from ..state_file import StateFileClaim, claim, set_aside

__all__ = ["NodeStateFile"]


class NodeStateFile:
    """The node's ``state_file`` (empty: none) and what became of it (:attr:`status`)."""

    def __init__(self, path: str) -> None:
        self.path = path
        self.status = "no state file"
        self._claim: StateFileClaim | None = None
        self._said = False  # a problem with the file is logged once; the start-up line points to it

    def startup_text(self) -> str:
        """The state file's part of the node's start-up line."""
        return f"{self.status.partition(':')[0]} (above)" if self._said else self.status

    def _problem(self, logger: Any, status: str, *, error: bool) -> None:
        self.status, self._said = status, True
        (logger.error if error else logger.warning)(status)

    def load(self, pipeline: Pipeline, logger: Any) -> None:
        """Resume from the file when it holds this configuration's state. The file is claimed
        first (:func:`rls_uncertainty.state_file.claim`): one that is not a regular file, or that
        another process holds, is refused in one line and the node runs without a state file. A
        file that exists but cannot be used (corrupt, crafted, another configuration's) is renamed
        aside (:func:`rls_uncertainty.state_file.set_aside`) so that the fresh state saved later
        never replaces it; if it cannot be moved, nothing is saved this run."""
        path = self.path
        if not path:
            return
        try:
            self._claim = claim(path)
        except StateFileError as exc:
            self.path = ""
            self._problem(logger, f"state file refused: {exc}; running without a state file", error=True)
            return
        if self._claim.removed:
            names = ", ".join(p.name for p in self._claim.removed)
            logger.info(f"removed {len(self._claim.removed)} temporary file(s) of interrupted saves of {path}: {names}")
        if not os.path.lexists(path):
            self.status = f"state file {path} not found: starting fresh"
            return
        try:
            pipeline.load_state(path)
        except StateFileError as exc:
            reason = str(exc)
        else:
            self.status = f"resumed from {path} ({pipeline.bank.k} samples)"
            return
        try:
            aside = set_aside(path)
        except OSError as exc:
            self.path = ""
            self.release()
            self._problem(logger, f"state file ignored: {reason}; it could not be moved aside ({exc}), so it is left "
                                  "as it is and no state is saved this run", error=True)
            return
        self._problem(logger, f"state file ignored: {reason}; kept as {aside}; a fresh state will be saved to {path}",
                      error=False)

    def save(self, pipeline: Pipeline, logger: Any) -> bool:
        """Save the state (True when there is a file to save to); a failure is logged."""
        if not self.path:
            return False
        try:
            pipeline.save_state(self.path)
        except OSError as exc:
            logger.error(f"cannot save state to {self.path}: {exc}")
        return True

    def release(self) -> None:
        """Free the file's lock (after the last save)."""
        if self._claim is not None:
            self._claim.release()
            self._claim = None

"""The optional dependencies: which pip extra installs which modules, and the one line said when
one is missing.

A plain ``pip install rls_uncertainty`` gives the estimator, ``simulate``, ``make-bag``,
``convert`` and ``replay --no-figures``; the rest comes with an extra (setup.py reads their
version ranges from requirements.txt): ``ros`` (the node and every command that talks DDS),
``figures`` (matplotlib), ``dashboard`` (the web server), ``campaign`` (Dask). Every import of an
optional module, lazy or at the top of a module that a command imports on demand, is made inside
:func:`optional`, which turns the ``ModuleNotFoundError`` of a module an extra provides into a
:class:`.errors.MissingExtra` naming the extra to install; any other missing module is a bug and
keeps its traceback.

Standard library only: the command line imports this before anything heavy.
"""

from __future__ import annotations

import importlib
from collections.abc import Iterator
from contextlib import contextmanager

from .errors import MissingExtra

__all__ = ["EXTRAS", "HINTS", "optional", "require"]

# Extra -> the top-level modules it provides (those the package imports).
EXTRAS: dict[str, tuple[str, ...]] = {
    "ros": ("rclpy", "rcl_interfaces", "builtin_interfaces", "std_msgs", "sensor_msgs", "geometry_msgs",
            "diagnostic_msgs", "std_srvs", "rosgraph_msgs", "ament_index_python"),
    "figures": ("matplotlib",),
    "dashboard": ("aiohttp",),
    "campaign": ("distributed", "dask"),
}
# What else may provide them, said after the pip command.
HINTS = {"ros": "source a ROS 2 Jazzy installation"}


def _message(extra: str, module: str, what: str, instead: str) -> str:
    need = f"{what} needs {module}" if what else f"{module} is not installed"
    others = " or ".join(h for h in (HINTS.get(extra, ""), instead) if h)
    return f"{need}: pip install 'rls_uncertainty[{extra}]'" + (f" (or {others})" if others else "")


@contextmanager
def optional(*extras: str, what: str = "", instead: str = "") -> Iterator[None]:
    """Imports (and code that imports) modules of the ``extras`` in the ``with`` block: a
    module of theirs that is missing raises :class:`.errors.MissingExtra` with one line naming
    ``what`` needs it, the extra that installs it and, when given, what to do ``instead``
    (``drawing the figures needs matplotlib: pip install 'rls_uncertainty[figures]' (or give
    --no-figures)``). Other import errors pass unchanged."""
    unknown = [e for e in extras if e not in EXTRAS]
    if unknown or not extras:
        raise TypeError(f"optional(): unknown extra(s) {unknown or '(none given)'}; known: {sorted(EXTRAS)}")
    try:
        yield
    except ModuleNotFoundError as exc:
        root = (exc.name or "").partition(".")[0]
        extra = next((e for e in extras if root in EXTRAS[e]), None)
        if extra is None:
            raise
        raise MissingExtra(_message(extra, root, what, instead), extra=extra, module=root) from exc


def require(extra: str, what: str = "", instead: str = "") -> None:
    """Import the ``extra``'s main module now (the first of :data:`EXTRAS`), so that a command
    that will need it says so before it starts its work (:func:`optional`'s error)."""
    with optional(extra, what=what, instead=instead):
        importlib.import_module(EXTRAS[extra][0])

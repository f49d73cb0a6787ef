"""Print the README's parameter table from config.PARAMETERS (the single source), or with
--check exit 1 when README.md's table differs from it.

    .venv/bin/python scripts/readme_parameters.py [--check]
"""

from __future__ import annotations

import sys
from pathlib import Path

from rls_uncertainty.config import PARAMETERS, ParamSpec

README = Path(__file__).resolve().parents[1] / "README.md"
HEAD = "| parameter | default | range | meaning |\n| --- | --- | --- | --- |\n"


def _default(spec: ParamSpec) -> str:
    d = spec.default
    if isinstance(d, bool):
        return "true" if d else "false"
    if isinstance(d, list):
        return "[" + ", ".join(d) + "]"
    if d == "":
        return '""'
    return str(d)


def _range(spec: ParamSpec) -> str:
    if spec.choices:
        return " / ".join(spec.choices)
    if spec.low is not None and spec.high is not None:
        return f"{spec.low:g} to {spec.high:g}"
    return ""


def table() -> str:
    rows = [f"| `{p.name}` | `{_default(p)}` | {_range(p)} | {p.description} |" for p in PARAMETERS]
    return HEAD + "\n".join(rows) + "\n"


def current(text: str) -> tuple[int, int]:
    start = text.index(HEAD)
    end = text.index("\n\n", start) + 1
    return start, end


def main() -> int:
    text = README.read_text()
    start, end = current(text)
    if "--check" in sys.argv:
        return 0 if text[start:end] == table() else 1
    if "--write" in sys.argv:
        README.write_text(text[:start] + table() + text[end:])
        return 0
    sys.stdout.write(table())
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

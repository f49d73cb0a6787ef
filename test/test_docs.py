"""The README and the manual under docs/: the two commands, the demo's output, the generated
parameter table, every parameter and output documented, links that resolve, every page
reachable from the README, and studies that use only the package's public names."""

from __future__ import annotations

import ast
import math
import re
import runpy
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
DOCS = ROOT / "docs"
STUDIES = DOCS / "studies"
SETUP_AND_DEMO = "bash scripts/setup.sh && .venv/bin/rls-uncertainty demo"
SETUP_CHECK_TEST = ("bash scripts/setup.sh && bash scripts/check.sh"
                    " && .venv/bin/python -m pytest -q -n 2 --dist loadfile")

# [text](target) in Markdown, not images; the target up to the first space or ')'.
_LINK = re.compile(r"(?<!!)\[[^\]]*\]\(([^)\s]+)\)")


def _pages() -> list[Path]:
    """Every Markdown page of the README and the manual (and msg_schemas' README)."""
    return [README, ROOT / "msg_schemas" / "README.md", *sorted(DOCS.rglob("*.md"))]


def _code_blocks(text: str) -> list[str]:
    return re.findall(r"```[a-z]*\n(.*?)```", text, flags=re.S)


def _slug(heading: str) -> str:
    """GitHub's anchor of a heading: lower case, punctuation but '-' and '_' dropped, spaces to '-'."""
    text = re.sub(r"[`*]", "", heading.strip().lower())
    return re.sub(r"[^\w\- ]", "", text).replace(" ", "-")


def _prose(page: Path) -> str:
    """The page without its code blocks and HTML comments."""
    return re.sub(r"```.*?```|<!--.*?-->", "", page.read_text(), flags=re.S)


def _anchors(page: Path) -> set[str]:
    text = _prose(page)
    return {_slug(m) for m in re.findall(r"^#+ (.+)$", text, flags=re.M)}


def _links(page: Path) -> list[tuple[Path, str]]:
    """(target file, anchor) of every relative link on the page, outside code blocks and comments."""
    text = _prose(page)
    out = []
    for target in _LINK.findall(text):
        if re.match(r"[a-z]+:", target):  # http:, https:, mailto:
            continue
        path, _, anchor = target.partition("#")
        out.append(((page.parent / path).resolve() if path else page, anchor))
    return out


def test_readme_gives_the_two_commands_and_ci_runs_the_second():
    blocks = [b.strip() for b in _code_blocks(README.read_text())]
    assert SETUP_AND_DEMO in blocks
    assert SETUP_CHECK_TEST in blocks
    ci = [line for line in (ROOT / ".ci" / "run").read_text().splitlines() if line and not line.startswith("#")]
    assert ci[-1] == SETUP_CHECK_TEST


def test_readme_is_at_most_250_lines():
    assert len(README.read_text().splitlines()) <= 250


def test_readme_promises_no_byte_identical_output_across_machines():
    text = README.read_text().lower()
    assert "byte-identical" not in text and "byte identical" not in text


def test_demo_output_in_the_readme_is_the_offline_replay_of_the_bundled_bag():
    """The README's demo table against the offline replay the demo prints beside the node. The
    table shows rounded numbers: each must be the rounding of the replay's value, up to the
    last-bit differences between machines (OpenBLAS picks its kernels by CPU; the replay's
    results agree across kernels to far better than 1e-9 relative), so a printed value may sit
    half a unit of its last digit plus 1e-9 relative away."""
    from rls_uncertainty.offline.bags import read_inputs
    from rls_uncertainty.offline.replay import run_pipeline
    from rls_uncertainty.ros.player import bundled_bag
    from rls_uncertainty.settings import config_dir, load_parameters_file, pipeline_config
    from rls_uncertainty.simulation.t2 import T2_TRUE

    block = next(b for b in _code_blocks(README.read_text()) if b.startswith("live node:"))
    config = pipeline_config(load_parameters_file(str(config_dir() / "t2.yaml")))
    result = run_pipeline(read_inputs(bundled_bag())[0], config)
    n = len(result.outputs)
    assert block.splitlines()[0] == f"live node: {n} samples published (offline replay: {n})"
    rows = {line.split()[0]: line.split()[1:] for line in block.splitlines() if line.startswith(("CZ_", "Cm_"))}
    last = result.outputs[-1]
    expected = {}
    for j, names in enumerate(result.pipeline.parameter_names):
        for i, name in enumerate(names):
            expected[name] = (last.theta[j, i], last.se_conventional[j, i], last.se[j, i])
    assert list(rows) == list(expected)
    for name, (true, *printed) in rows.items():
        assert true == ("-" if name not in T2_TRUE else f"{T2_TRUE[name]:.3f}")
        estimate, se_conv, se_corr = expected[name]
        for text, value in zip(printed, (estimate, se_conv, se_corr, se_corr / se_conv), strict=True):
            decimals = len(text.partition(".")[2])
            assert math.isclose(float(text), value, rel_tol=1e-9, abs_tol=0.5 * 10**-decimals * (1 + 1e-9)), (
                name, text, value)


def test_node_page_holds_exactly_the_generated_parameter_table():
    """docs/node.md's table is what scripts/parameter_table.py makes of config.PARAMETERS
    (run it with --write after changing a parameter)."""
    script = runpy.run_path(str(ROOT / "scripts" / "parameter_table.py"))
    text = (DOCS / "node.md").read_text()
    start, end = script["current"](text)
    assert text[start:end] == script["table"]()


def test_node_page_documents_every_parameter_topic_and_service():
    from rls_uncertainty.datapath.inputs import MESSAGE_TYPES
    from rls_uncertainty.datapath.outputs import fit_topics, output_topics
    from rls_uncertainty.settings import PARAMETERS

    text = (DOCS / "node.md").read_text()
    body = text[: text.index("<!-- parameter table")]  # documented outside the generated table too
    missing = [p.name for p in PARAMETERS if f"`{p.name}`" not in text]
    assert not missing, f"parameters not in docs/node.md: {missing}"
    for topic, msgtype in MESSAGE_TYPES.items():
        assert f"| `{topic}` | `{msgtype.replace('/msg/', '/')}` | in" in body, topic
    for topic, msgtype in output_topics(["M"], frequency=True) + fit_topics(["M"]):
        assert f"| `~/{topic}` | `{msgtype.replace('/msg/', '/')}` | out" in body, topic
    for name in ("/diagnostics", "~/reset", "~/enable", "state_file", "use_sim_time"):
        assert name in body, name


def test_every_relative_link_resolves_to_a_file_and_anchor():
    broken = []
    for page in _pages():
        for target, anchor in _links(page):
            if not target.exists():
                broken.append(f"{page.relative_to(ROOT)}: {target}")
            elif anchor and target.suffix == ".md" and anchor not in _anchors(target):
                broken.append(f"{page.relative_to(ROOT)}: {target.relative_to(ROOT)}#{anchor}")
    assert not broken, broken


def test_every_docs_page_is_reachable_from_the_readme():
    seen, todo = {README.resolve()}, [README.resolve()]
    while todo:
        page = todo.pop()
        for target, _anchor in _links(page):
            if target.suffix == ".md" and target.exists() and target not in seen:
                seen.add(target)
                todo.append(target)
    unreachable = [p.relative_to(ROOT) for p in DOCS.rglob("*.md") if p.resolve() not in seen]
    assert not unreachable, unreachable


# `module.name` or `rls_uncertainty.module.name` in backticks, optionally called: `outputs.parse_stamp_label()`.
_CODE_REF = re.compile(r"`(?:rls_uncertainty\.)?([A-Za-z_][\w.]*\.[A-Za-z_]\w*)(?:\(\))?`")
_FILE_SUFFIXES = {"py", "csv", "md", "yaml", "json", "png", "npz", "mcap", "xml", "txt", "rst", "toml", "sh", "msg"}


def _package_modules() -> dict[str, Path]:
    """Dotted name (relative to the package) -> file, for every module of rls_uncertainty."""
    package = ROOT / "rls_uncertainty"
    out = {}
    for path in sorted(package.rglob("*.py")):
        if "node_modules" in path.parts or (path.name == "__init__.py" and path.parent == package):
            continue
        parts = path.relative_to(package).with_suffix("").parts
        out[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    return out


def test_every_name_of_the_package_the_docs_cite_exists():
    """A backticked `module.name` (`outputs.parse_stamp_label`, `config.PARAMETERS`,
    `pipeline.Pipeline.counters`) whose head is a module of the package names something that
    module has: a renamed or removed function shows here, not in a reader's traceback. ROS
    parameter names (`estimator.lags`, `limits.angular_rate`) and file names are not code."""
    import importlib

    from rls_uncertainty.settings import PARAMETERS

    parameters = {p.name for p in PARAMETERS}
    modules = _package_modules()
    missing = []
    for page in _pages():
        for dotted in _CODE_REF.findall(page.read_text()):
            parts = dotted.split(".")
            if dotted in parameters or parts[-1] in _FILE_SUFFIXES:
                continue
            heads = [i for i in range(len(parts), 0, -1) if ".".join(parts[:i]) in modules]
            if not heads:
                continue
            obj = importlib.import_module("rls_uncertainty." + ".".join(parts[: heads[0]]))
            for attribute in parts[heads[0]:]:
                if not hasattr(obj, attribute):
                    missing.append(f"{page.relative_to(ROOT)}: {dotted}")
                    break
                obj = getattr(obj, attribute)
    assert not missing, missing


def test_architecture_page_names_every_module_of_the_package():
    """docs/architecture.md's module table has a line for every module (a subpackage's modules
    by name in its line), so a new module is placed on the map when it is added."""
    text = (DOCS / "architecture.md").read_text()
    unnamed = []
    for name in _package_modules():
        spellings = (f"`{name}.py`", f"`{name}/`", f"`{name.rpartition('.')[2]}`")
        if not any(spelling in text for spelling in spellings):
            unnamed.append(name)
    assert not unnamed, unnamed


def _studies() -> list[Path]:
    return sorted(p for p in STUDIES.iterdir() if p.is_dir())


def test_each_study_is_one_script_and_its_report():
    """A study is its script and its report, and at most a results/ directory of the files the
    script writes (tables the report and the manual quote)."""
    assert _studies()
    for study in _studies():
        names = sorted(p.name for p in study.iterdir() if p.name != "__pycache__")
        assert names in (["REPORT.md", "study.py"], ["REPORT.md", "results", "study.py"]), study
        if (study / "results").exists():
            assert all(p.is_file() for p in (study / "results").iterdir()), study


@pytest.mark.parametrize("study", _studies(), ids=lambda p: p.name)
def test_studies_use_only_public_names_of_the_package(study):
    """No attribute or imported name with a leading underscore (dunders aside): a study that
    reaches into the package's internals breaks silently when they change."""
    tree = ast.parse((study / "study.py").read_text())
    private = [
        node.attr for node in ast.walk(tree)
        if isinstance(node, ast.Attribute) and node.attr.startswith("_") and not node.attr.startswith("__")
    ]
    private += [
        alias.name for node in ast.walk(tree) if isinstance(node, ast.ImportFrom) and node.module
        and node.module.startswith("rls_uncertainty") for alias in node.names if alias.name.startswith("_")
    ]
    assert not private, private


@pytest.mark.parametrize("study", _studies(), ids=lambda p: p.name)
def test_studies_run_in_quick_mode(study):
    """Each study's --quick mode runs against the current package and prints its results (a
    table, or the counts of a sweep): a study whose script no longer runs is caught here."""
    run = subprocess.run([sys.executable, str(study / "study.py"), "--quick"], capture_output=True, text=True,
                         timeout=600, cwd=ROOT)
    assert run.returncode == 0, run.stderr[-2000:]
    assert any(char.isdigit() for char in run.stdout), run.stdout[-2000:]  # results, not silence


# History does not belong in the manual: it states what the shipped code does, each figure with
# the command that makes it. A commit id (7 to 40 hex digits with a digit and a letter), a
# helper branch name (h-...) or a date in the README, under docs/, in the config files' comments
# or in the package's docstrings and comments is flagged. Hex in code blocks is command output
# (a CRC, a truncated SHA-256), and the recording names of the flight data (totter_9752ed20)
# are names, not commits.
_COMMIT = re.compile(r"(?<![\w/#.-])(?=[0-9a-f]*\d)(?=[0-9a-f]*[a-f])[0-9a-f]{7,40}(?!\w)")
_BRANCH = re.compile(r"(?<![\w-])h-[a-z][a-z0-9]*\b")
_DATE = re.compile(r"\b(19|20)\d\d-[01]\d-[0-3]\d\b")


def _manual() -> list[Path]:
    """The README, every page and study under docs/, the other READMEs, the config files, and
    every Python file the package, its scripts and benchmarks ship."""
    return [*_pages(), ROOT / "bags" / "README.md", *sorted((ROOT / "config").rglob("*.yaml")),
            *sorted((ROOT / "rls_uncertainty").rglob("*.py")), *sorted(STUDIES.rglob("*.py")),
            *sorted((ROOT / "benchmarks").glob("*.py")), *sorted((ROOT / "scripts").iterdir()),
            *sorted((ROOT / "launch").glob("*.py")), *sorted((ROOT / "examples").rglob("*.py"))]


def _recording_ids() -> set[str]:
    """The flight recordings' ids, from the aircraft files named after them."""
    return {p.stem.rpartition("_")[2] for p in (ROOT / "config" / "aircraft").glob("twin_otter_*.yaml")}


def history_in(text: str, markdown: bool, allowed: set[str] = frozenset()) -> list[str]:
    """Commit ids, branch names and dates in ``text`` (hex outside Markdown code blocks only)."""
    found = [m.group(0) for rx in (_BRANCH, _DATE) for m in rx.finditer(text)]
    prose = re.sub(r"```.*?```", "", text, flags=re.S) if markdown else text
    found += [m.group(0) for m in _COMMIT.finditer(prose) if m.group(0) not in allowed]
    return found


def test_the_manual_holds_no_history():
    allowed = _recording_ids()
    assert "9752ed20" in allowed
    problems = []
    for path in _manual():
        if path.is_file() and path.suffix in {".md", ".yaml", ".py", ".sh", ""}:
            for word in history_in(path.read_text(encoding="utf-8"), path.suffix == ".md", allowed):
                problems.append(f"{path.relative_to(ROOT)}: {word}")
    assert not problems, "commit ids, branch names or dates in the manual:\n  " + "\n  ".join(problems)


def test_the_history_check_finds_what_it_is_for():
    planted = ("Measured at commit fadea67 on branch h-campaign (2026-11-25); the SHA-256 of a bag in a block:\n"
               "```\nde4b83f2c876...\n```\nrecording totter_9752ed20, colour #1f77b4, file a/deadbeef, 12345678 runs")
    assert history_in(planted, True, {"9752ed20"}) == ["h-campaign", "2026-11-25", "fadea67"]
    assert "de4b83f2c876" in history_in(planted, False)  # outside Markdown, a block is no excuse

"""The README documents every parameter and output of the node."""

from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_readme_documents_every_parameter_and_output():
    from rls_uncertainty.config import PARAMETERS

    text = (ROOT / "README.md").read_text()
    missing = [p.name for p in PARAMETERS if f"`{p.name}`" not in text]
    assert not missing, f"parameters not in the README: {missing}"
    for topic in ("~/sample_stamp", "~/M/estimates", "~/M/standard_errors", "~/M/standard_errors_conventional",
                  "/diagnostics", "~/reset", "~/enable"):
        assert topic in text


def test_readme_parameter_table_is_generated_from_the_parameter_table():
    """README's parameter table is exactly what scripts/readme_parameters.py makes of
    config.PARAMETERS (run it with --write after changing a parameter)."""
    import runpy

    script = runpy.run_path(str(ROOT / "scripts" / "readme_parameters.py"))
    assert script["table"]() in (ROOT / "README.md").read_text()

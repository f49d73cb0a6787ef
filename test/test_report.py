"""The one results table of simulate, replay and demo (rls_uncertainty/offline/report.py)."""

import math

import pytest

from rls_uncertainty.offline.report import ResultRow, results_table, rows_from_arrays


def test_the_demo_lines_of_the_readme_are_reproduced_exactly():
    rows = rows_from_arrays(
        ["CZ_0", "CZ_alpha", "Cm_q"], [-0.11781, -3.60693, -40.65961], [0.00411, 0.04874, 2.24731],
        [0.01362, 0.16139, 7.38941], {"CZ_alpha": -3.911, "Cm_q": -53.25})
    assert results_table(rows).splitlines() == [
        "parameter        true   estimate  SE conv.  SE corr. corr/conv",
        "--------------------------------------------------------------",
        "CZ_0                -    -0.1178    0.0041    0.0136      3.31",
        "CZ_alpha       -3.911    -3.6069    0.0487    0.1614      3.31",
        "Cm_q          -53.250   -40.6596    2.2473    7.3894      3.29",
    ]


def test_small_standard_errors_keep_two_significant_digits():
    row = ResultRow("Cl_0", 0.00042293, 1.688e-05, 4.784e-05)
    line = results_table([row]).splitlines()[2].split()
    # 1 - floor(log10(1.688e-5)) = 6 decimals; the ratio comes from the unrounded values.
    assert line == ["Cl_0", "0.000423", "0.000017", "0.000048", f"{4.784e-05 / 1.688e-05:.2f}"]
    # At least four decimals whatever the size of the errors.
    assert results_table([ResultRow("Cm_q", -40.65961, 2.2, 7.4)]).splitlines()[2].split()[1] == "-40.6596"


def test_true_column_only_when_known_and_undefined_values_are_dashes():
    rows = [ResultRow("a", 1.0, 0.0, 0.5), ResultRow("b", 2.0, math.nan, 0.5), ResultRow("c", 3.0, 0.1, 0.2)]
    lines = results_table(rows).splitlines()
    assert lines[0].split() == ["parameter", "estimate", "SE", "conv.", "SE", "corr.", "corr/conv"]
    assert [line.split()[-1] for line in lines[2:]] == ["-", "-", "2.00"]
    with_true = results_table(rows, show_true=True).splitlines()
    assert with_true[0].split()[1] == "true" and [line.split()[1] for line in with_true[2:]] == ["-", "-", "-"]
    # A true value is never rounded: three decimals, more when it has them.
    assert results_table([ResultRow("d", 0.0, 0.1, 0.1, 0.00125)]).splitlines()[2].split()[1] == "0.00125"


def test_columns_widen_for_long_names_and_numbers_and_stay_aligned():
    rows = [ResultRow("a_very_long_parameter_name", -123456.789, 0.5, 1.5, -100000.0),
            ResultRow("x", 1.0, 0.5, 1.0)]
    lines = results_table(rows).splitlines()
    assert len({len(line) for line in lines}) == 1
    assert lines[2].startswith("a_very_long_parameter_name  ")
    assert lines[2].split()[1:3] == ["-100000.000", "-123456.7890"]


def test_rows_from_arrays_refuses_arrays_of_different_lengths():
    with pytest.raises(ValueError):
        rows_from_arrays(["a", "b"], [1.0], [0.1, 0.1], [0.2, 0.2])

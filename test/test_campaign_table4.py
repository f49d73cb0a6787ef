"""campaign/table4.py: Table 4 (Section IV.B) from per-maneuver rows, against numpy's mean and
sample standard deviation computed here; the failed maneuvers are left out and named; the CSV
files hold the documented columns at full precision. No ROS."""

from __future__ import annotations

import csv
import io
import math

import numpy as np
import pytest

from rls_uncertainty.campaign import TABLE4_COLUMNS, ManeuverResult, ParameterResult
from rls_uncertainty.campaign.run import MANEUVER_COLUMNS
from rls_uncertainty.campaign.table4 import maneuvers_csv, summary_text, table4, table4_csv, table4_markdown


def _results(rng, n, failed=()):
    out = []
    for i in range(n):
        name = f"m{i}"
        if i in failed:
            rows = tuple(ParameterResult(name, "Cm", p, math.nan, math.nan, math.nan, math.nan, 0, math.nan,
                                         "failed: no such bag") for p in ("Cm_alpha", "Cm_q"))
        else:
            v = rng.normal(size=(2, 4)) ** 2
            rows = tuple(ParameterResult(name, "Cm", p, *v[k], 600, 0.9, "ok",
                                         state="converged" if v[k, 0] > 0.5 else "settling")
                         for k, p in enumerate(("Cm_alpha", "Cm_q")))
        out.append(ManeuverResult(name, rows))
    return out


def test_table4_is_the_mean_of_each_column_and_the_sample_deviation_of_the_estimates():
    rng = np.random.default_rng(4)
    results = _results(rng, 9, failed={3, 7})
    rows = table4(results)
    assert [(r.model, r.parameter) for r in rows] == [("Cm", "Cm_alpha"), ("Cm", "Cm_q")]
    for k, row in enumerate(rows):
        used = [res.rows[k] for i, res in enumerate(results) if i not in {3, 7}]
        est = np.array([u.estimate for u in used])
        assert row.maneuvers == 7
        assert row.converged == sum(u.state == "converged" for u in used)
        assert row.mean == pytest.approx(est.mean(), rel=1e-15)
        assert row.scatter == pytest.approx(math.sqrt(((est - est.mean()) ** 2).sum() / 6), rel=1e-14)
        for name in ("se_conventional", "se_corrected_all", "se_corrected"):
            assert getattr(row, name) == pytest.approx(np.mean([getattr(u, name) for u in used]), rel=1e-15)
        assert row.ratios == (row.se_conventional / row.scatter, row.se_corrected_all / row.scatter,
                              row.se_corrected / row.scatter)


def test_one_maneuver_has_no_scatter_and_none_has_no_mean():
    one = table4(_results(np.random.default_rng(1), 1))
    assert one[0].maneuvers == 1 and math.isnan(one[0].scatter) and all(math.isnan(x) for x in one[0].ratios)
    none = table4(_results(np.random.default_rng(1), 2, failed={0, 1}))
    assert none[0].maneuvers == 0 and math.isnan(none[0].mean)


def test_the_csv_files_hold_every_value_at_full_precision():
    results = _results(np.random.default_rng(2), 4, failed={1})
    rows = list(csv.reader(io.StringIO(maneuvers_csv(results))))
    assert tuple(rows[0]) == MANEUVER_COLUMNS and len(rows) == 1 + 8
    col = {name: i for i, name in enumerate(rows[0])}
    first = results[0].rows[0]
    assert float(rows[1][col["estimate"]]) == first.estimate and rows[1][col["method"]] == "time"
    assert rows[1][col["status"]] == "ok" and rows[1][col["state"]] == first.state
    assert float(rows[1][col["se_percent"]]) == 100 * first.se_corrected / abs(first.estimate)
    assert rows[3][col["estimate"]] == "" and rows[3][col["status"]] == "failed: no such bag"  # empty cells
    assert rows[3][col["se_percent"]] == ""
    t4 = list(csv.reader(io.StringIO(table4_csv(table4(results)))))
    assert tuple(t4[0]) == TABLE4_COLUMNS
    assert TABLE4_COLUMNS[:10] == ("model", "parameter", "method", "maneuvers", "converged", "mean",
                                   "se_conventional", "se_corrected_all", "se_corrected", "scatter")
    assert float(t4[1][5]) == table4(results)[0].mean and t4[1][2] == "time"
    assert int(t4[1][4]) == sum(r.rows[0].state == "converged" for r in results if r.rows[0].ok)


def test_the_markdown_and_the_summary_name_the_maneuvers_not_used():
    results = _results(np.random.default_rng(3), 5, failed={2})
    md = table4_markdown(table4(results), results, 50)
    assert "| Cm | Cm_q | 4 |" in md and "- m2: failed: no such bag" in md and "SE corrected, 50 lags" in md
    text = summary_text(table4(results), results, 50)
    assert "4 of 5 maneuvers used" in text and "m2: failed: no such bag" in text

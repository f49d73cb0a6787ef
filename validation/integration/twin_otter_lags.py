"""Run: rls-uncertainty convert /work/shared/flight_data/totter_f1_0NN --mapping
msg_schemas/fti_msgs/mapping.yaml --out BAGS/totter_f1_0NN (017 and 014), then
PYTHONPATH=$PWD python validation/integration/twin_otter_lags.py BAGS OUT.

Issue 14 validation on the Twin Otter lateral recordings: replay (the package's replay())
with estimator.lags 50, all, and lag_selection auto (its default residual burn-in of 50
samples; "auto_burn0": burn-in 0, the paper's Eq. 17, as before the option existed); chosen
lags and corrected SEs at the end."""

import json
import sys
from pathlib import Path

import numpy as np

from rls_uncertainty.config import load_parameters_file
from rls_uncertainty.replay import replay

rows = {}
for rec in ("totter_f1_017", "totter_f1_014"):
    base = load_parameters_file(Path(__file__).resolve().parents[2] / "config" / "twin_otter_lateral.yaml")
    base["aircraft"] = "twin_otter_" + rec.split("_", 1)[1]
    variants = {
        "auto": {"estimator.lag_selection": "auto"},
        "auto_burn0": {"estimator.lag_selection": "auto", "estimator.residual_burn_in": 0},
        "50": {"estimator.lags": 50},
        "all": {"estimator.lags": -1},
        "auto100": {"estimator.lag_selection": "auto", "estimator.max_lags": 100},
    }
    out = {}
    for name, over in variants.items():
        res = replay(
            f"{sys.argv[1]}/{rec}",
            {**base, **over},
            f"{sys.argv[2]}/{rec}_{name}",
            progress=False,
            plots=False,
            force=True,
        )
        pipe, last = res.pipeline, res.outputs[-1]
        lags_series = np.array([o.lags for o in res.outputs])
        changes = (np.diff(lags_series, axis=0) != 0).sum(axis=0)
        out[name] = {
            "lags": last.lags.tolist(),
            "changes": changes.tolist(),
            "samples": len(res.outputs),
            "models": [m.output for m in pipe.models],
            "names": [list(n) for n in pipe.parameter_names],
            "theta": [last.theta[j, : len(n)].tolist() for j, n in enumerate(pipe.parameter_names)],
            "se": [last.se[j, : len(n)].tolist() for j, n in enumerate(pipe.parameter_names)],
            "se_conv": [last.se_conventional[j, : len(n)].tolist() for j, n in enumerate(pipe.parameter_names)],
        }
        print(rec, name, out[name]["lags"], out[name]["changes"], flush=True)
    rows[rec] = out
with open(f"{sys.argv[2]}/twin_otter_lags.json", "w") as fh:
    json.dump(rows, fh, indent=1)

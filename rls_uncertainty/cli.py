"""``rls-uncertainty``: the package's command line, one subcommand per job."""

from __future__ import annotations

import argparse
import sys

import numpy as np

__all__ = ["main"]


def _demo(args: argparse.Namespace) -> int:
    """Estimator on a seeded simulated T-2 maneuver (Section IV.A), one sample at a time."""
    from .estimator import EstimatorBank
    from .simulation import T2_MODELS, T2_TRUE, add_noise, reduce_short_period, simulate_short_period

    record = add_noise(simulate_short_period(), args.noise / 100.0, np.random.default_rng(args.seed))
    t, data = reduce_short_period(record)
    models = [m for m in T2_MODELS]
    bank = EstimatorBank([len(m.regressors) for m in models], args.lags, args.window, args.forgetting)
    z = np.empty(len(models))
    for k in range(t.size):
        rows = [data[m.output][0][k] for m in models]
        for j, m in enumerate(models):
            z[j] = data[m.output][1][k]
        bank.update(rows, z)
    lags = "all" if args.lags is None else args.lags
    print(
        f"T-2 short-period maneuver, {args.noise:g}% band-limited noise (seed {args.seed}), "
        f"{t.size} samples at 50 Hz, {lags} lags, {args.window} window\n"
    )
    header = f"{'parameter':<12}{'true':>10}{'estimate':>11}{'SE conv.':>11}{'SE corr.':>11}{'corr/conv':>11}"
    print(header)
    print("-" * len(header))
    for j, m in enumerate(models):
        theta = bank.theta(j)
        se_conv = bank.standard_errors(j, "conventional")
        se_corr = bank.standard_errors(j, "corrected")
        for name, th, sv, sc in zip(m.parameter_names, theta, se_conv, se_corr):
            true = T2_TRUE.get(name)
            true_s = f"{true:10.3f}" if true is not None else f"{'-':>10}"
            print(f"{name:<12}{true_s}{th:11.4f}{sv:11.4f}{sc:11.4f}{sc / sv:11.2f}")
    print(
        "\nConventional standard errors assume white residuals (Eq. 13); corrected ones use the "
        "recursive residual autocorrelation (Eqs. 17-22)."
    )
    return 0


def _montecarlo(args: argparse.Namespace) -> int:
    """Table 3 of the paper: every noise level, ``--runs`` runs each, on every core."""
    from pathlib import Path

    from .montecarlo import LEVELS, run_table3, write_outputs

    levels = LEVELS if args.levels is None else tuple(x / 100.0 for x in args.levels)
    print(f"Monte Carlo: {args.runs} runs x {len(levels)} levels, {args.lags} lags, {args.jobs or 'all'} processes")
    results = run_table3(args.runs, levels, n_lags=args.lags, jobs=args.jobs)
    paths = write_outputs(results, Path(args.out), figures=not args.no_figures)
    print(Path(paths["md"]).read_text())
    for key, path in paths.items():
        print(f"wrote {path}")
    return 0


def _lags(value: str):
    if value in ("all", "none", "None"):
        return None
    n = int(value)
    if n < 0:
        raise argparse.ArgumentTypeError("lags must be >= 0 or 'all'")
    return n


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="rls-uncertainty",
        description="Recursive least squares with colored-residual parameter uncertainty.",
    )
    sub = parser.add_subparsers(dest="command", required=True)
    demo = sub.add_parser("demo", help="estimate the T-2 derivatives of a simulated maneuver")
    demo.add_argument("--noise", type=float, default=20.0, help="band-limited noise, percent (default 20)")
    demo.add_argument("--seed", type=int, default=250, help="noise seed (default 250)")
    demo.add_argument("--lags", type=_lags, default=50, help="retained lags, or 'all' (default 50)")
    demo.add_argument("--window", choices=("truncated", "bartlett"), default="truncated")
    demo.add_argument("--forgetting", type=float, default=1.0)
    demo.set_defaults(func=_demo)

    mc = sub.add_parser("montecarlo", help="reproduce Table 3 and Figs. 5-7 of the paper")
    mc.add_argument("--runs", type=int, default=250, help="runs per noise level (default 250)")
    mc.add_argument("--out", required=True, help="output directory")
    mc.add_argument("--levels", type=float, nargs="+", help="noise levels in percent (default 0 5 10 15 20)")
    mc.add_argument("--lags", type=int, default=50, help="retained lags (default 50)")
    mc.add_argument("--jobs", type=int, default=None, help="processes (default: every core)")
    mc.add_argument("--no-figures", action="store_true", help="skip the PNG figures")
    mc.set_defaults(func=_montecarlo)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except (ValueError, OSError) as exc:
        print(f"rls-uncertainty {args.command}: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())

"""``make-bag`` and ``convert``: replay bags on the node's standard input topics."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from ..errors import ConfigError
from ..simulation.multisine import MAX_INPUT_AMPLITUDE
from .flags import FORCE_HELP, add_progress, integer, progress_mode, real
from .simulation import noise_on, noise_on_name

__all__ = ["add_make_bag", "add_convert"]


def _gust(value: str) -> float:
    """--gust-intensity: sigma_w in m/s (a number >= 0) or light / moderate / severe
    (MIL-F-8785C low altitude, :data:`..simulation.turbulence.LOW_ALTITUDE_SIGMA_W`)."""
    from ..simulation.turbulence import LOW_ALTITUDE_SIGMA_W

    if value in LOW_ALTITUDE_SIGMA_W:
        return LOW_ALTITUDE_SIGMA_W[value]
    try:
        return real(0.0)(value)
    except argparse.ArgumentTypeError:
        raise argparse.ArgumentTypeError(f"must be sigma_w in m/s (a number >= 0) or one of "
                                         f"{', '.join(LOW_ALTITUDE_SIGMA_W)}, got {value!r}") from None


def _amplitude(args: argparse.Namespace) -> str:
    """`` at 0.3 x Table 2's elevator amplitude`` (nothing at the nominal 1)."""
    return "" if args.input_amplitude == 1.0 else f" at {args.input_amplitude:g} x Table 2's elevator amplitude"


def _make_campaign(args: argparse.Namespace) -> int:
    """make-bag --campaign N: N seeded T-2 maneuvers in Dryden turbulence, one bag each."""
    from ..offline.bags import write_campaign_bags
    from ..simulation.t2 import SimulationConfig
    from ..simulation.turbulence import DrydenVertical, scale_length

    if args.gust_intensity is None:
        raise ConfigError("--campaign needs --gust-intensity (sigma_w in m/s, or light, moderate or severe)")
    gust = DrydenVertical(args.gust_intensity, scale_length(SimulationConfig().altitude))
    paths = write_campaign_bags(args.out, args.campaign, gust, band_level=args.noise / 100.0,
                                band_limited_on=noise_on(args.noise_on), seed=args.seed, force=args.force,
                                input_amplitude=args.input_amplitude, progress=progress_mode(args))
    print(f"wrote {len(paths)} replay bags to {args.out}: T-2 maneuvers{_amplitude(args)} in Dryden vertical gusts "
          f"sigma_w "
          f"{gust.sigma:.3g} m/s, L_w {gust.scale_length:.0f} m, {args.noise:g}% band-limited noise on "
          f"{noise_on_name(args.noise_on)}, seed {args.seed} (settings in {Path(args.out) / 'campaign.yaml'})")
    return 0


def _make_flight(args: argparse.Namespace) -> int:
    """make-bag --flight: a flight-test day as one recording, with truth.csv beside the bag."""
    from ..offline.flight_bag import TRUTH_FILE, write_flight_bag

    if args.campaign is not None:
        raise ConfigError("--flight and --campaign are two kinds of output: give one")
    if args.input_amplitude != 1.0:
        raise ConfigError("--input-amplitude is not used with --flight (every maneuver is Table 2's multisine)")
    out = args.out or "bags/t2_flight"
    flight = write_flight_bag(out, args.seed, force=args.force, band_level=args.noise / 100.0,
                              band_limited_on=noise_on(args.noise_on), gust_sigma=args.gust_intensity)
    conditions = sorted({m.condition for m in flight.maneuvers})
    print(f"wrote {out}: a {flight.duration:.0f} s flight, {len(flight.maneuvers)} T-2 maneuvers at conditions "
          f"{', '.join(conditions)} between trim legs, Dryden vertical gusts, {args.noise:g}% band-limited noise on "
          f"{noise_on_name(args.noise_on)}, seed {args.seed}, test points on /test_point; the truth in "
          f"{Path(out) / TRUTH_FILE}")
    return 0


def _make_bag(args: argparse.Namespace) -> int:
    """Write the seeded T-2 maneuver on the node's standard input topics."""
    from ..offline.bags import write_t2_bag

    if args.flight:
        return _make_flight(args)
    args.out = args.out or "bags/t2_maneuver"
    if args.campaign is not None:
        return _make_campaign(args)
    if args.gust_intensity is not None:
        raise ConfigError("--gust-intensity sets the turbulence of a simulated campaign or flight: give --campaign N "
                          "or --flight")
    from ..simulation.t2 import SIGNALS

    on = SIGNALS if args.noise_on is None else noise_on(args.noise_on)  # the bundled bag's: all four
    path = write_t2_bag(args.out, args.noise / 100.0, args.seed, force=args.force, band_limited_on=on,
                        input_amplitude=args.input_amplitude)
    size = sum(f.stat().st_size for f in path.iterdir())
    print(f"wrote {path} ({size / 1e6:.2f} MB): T-2 maneuver{_amplitude(args)}, {args.noise:g}% band-limited noise, "
          f"seed {args.seed}")
    return 0


def _convert(args: argparse.Namespace) -> int:
    from ..offline.bags import convert

    counts = convert(args.bag, args.mapping, args.out, schemas=args.schemas, force=args.force)
    for topic, n in counts.items():
        print(f"{topic:<20}{n:>8} messages")
    print(f"wrote {args.out}")
    return 0


def add_make_bag(sub: Any) -> None:
    mb = sub.add_parser("make-bag", help="write the seeded T-2 maneuver as a bag on the standard input topics")
    mb.add_argument("--out", help="bag directory (default bags/t2_maneuver; with --flight bags/t2_flight)")
    mb.add_argument("--noise", type=real(0.0), default=20.0, help="band-limited noise, percent (default 20)")
    mb.add_argument("--seed", type=integer(0), default=250, help="noise seed (default 250)")
    mb.add_argument("--campaign", type=integer(1), metavar="N",
                    help="write N maneuvers flown in turbulence, one replay bag each, into --out (a campaign for "
                         "rls-uncertainty campaign; docs/campaign.md)")
    mb.add_argument("--flight", action="store_true",
                    help="write one recording of a flight-test day: trim legs in gusts and 12 T-2 maneuvers at three "
                         "airspeeds, test points on /test_point, truth.csv beside the bag (docs/maneuvers.md)")
    mb.add_argument("--gust-intensity", type=_gust, metavar="SIGMA_W",
                    help="with --campaign or --flight: RMS vertical gust in m/s, or light, moderate, severe "
                         "(MIL-F-8785C low altitude: 0.77, 1.54, 2.31 m/s; --flight's default light)")
    mb.add_argument("--noise-on", choices=("all", "responses"),
                    help="measured signals carrying the band-limited noise: 'all' (elevator, alpha, q, a_z) or "
                         "'responses' (alpha, q, a_z) (default: all for one maneuver, the bundled bag's; with "
                         "--campaign the simulation's, responses: docs/validation.md, Table 3)")
    mb.add_argument("--input-amplitude", type=real(0.0, high=MAX_INPUT_AMPLITUDE), default=1.0, metavar="F",
                    help="the elevator multisine at F x Table 2's amplitude, in [0, 10]; 0: no maneuver (the "
                         "elevator shows only its sensor noise, which stays at the nominal maneuver's scale); "
                         "default 1, the nominal maneuver")
    mb.add_argument("--force", action="store_true", help=FORCE_HELP)
    add_progress(mb)
    mb.set_defaults(func=_make_bag)


def add_convert(sub: Any) -> None:
    cv = sub.add_parser("convert", help="recorded bag + mapping file -> replay bag on the standard topics")
    cv.add_argument("bag", help="ROS 2 bag (MCAP or sqlite3; directory or file) or ROS 1 bag")
    cv.add_argument("--mapping", required=True, help="mapping YAML (e.g. msg_schemas/fti_msgs/mapping.yaml)")
    cv.add_argument("--out", required=True, help="output bag directory")
    cv.add_argument("--schemas", action="append", help="extra .msg directory (PKG/msg/NAME.msg); repeatable")
    cv.add_argument("--force", action="store_true", help=FORCE_HELP)
    cv.set_defaults(func=_convert)

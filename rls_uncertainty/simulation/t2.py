"""T-2 short-period simulation of Section IV.A (Eq. 25) with the paper's noise model.

134 ft/s, 1370 ft standard atmosphere, 4.8 deg trim angle of attack, Table 1 properties,
Table 3 true values, Table 2 elevator multisine from 0.5 s, 12 s record sampled at 50 Hz.
The continuous dynamics are integrated on a 1 kHz grid (the multisine is smooth: a zero-order
hold at 50 Hz visibly biases C_m_q) and then sampled. Noise: wide-band white noise at the
signal-to-noise ratios 40, 12, 30, 40 (elevator, alpha, q, a_z; RMS signal variation over RMS
noise) plus band-limited noise (white noise through a fifth-order Chebyshev low-pass at 2 Hz)
scaled to a fraction of each signal's RMS variation. Seeded and deterministic.

Turbulence (:mod:`.turbulence`, a Dryden vertical gust ``w_g``, positive up): the
aerodynamics see the aerodynamic angle of attack ``alpha_a = alpha + w_g / V`` (``alpha`` the
inertial one of Eq. 25a, ``w_g`` taken along body z, within the 4.8 deg trim angle), so
Eq. 25a-b become

    d(alpha)/dt = qbar S / (m V) (C_Z_alpha alpha_a + C_Z_delta_e delta_e) + q
    dq/dt       = qbar S cbar / I_yy (C_m_alpha alpha_a + cbar / (2 V) C_m_q q + C_m_delta_e delta_e)
    a_z         = qbar S / m (C_Z_alpha alpha_a + C_Z_delta_e delta_e)

and the vane reads ``alpha_a`` (plus its noise): the gust is one more input ``w_g / V``,
simulated by superposition on the integration grid. The sensor noise keeps the calm-air
scale (the RMS variation of each signal without the gust), since it belongs to the sensor.
"""

from __future__ import annotations

from collections.abc import Collection, Iterator
from dataclasses import dataclass, field, replace

import numpy as np
import numpy.typing as npt
from scipy import signal

from ..aero.coefficients import FlightState, coefficients, regressor_matrix, regressors
from ..aero.differentiation import DifferentiatorConfig, differentiate
from ..aero.models import AircraftConfig, ModelConfig
from ..errors import ConfigError
from ..settings.models import load_aircraft
from .multisine import MAX_INPUT_AMPLITUDE, T2_TABLE2, Multisine
from .turbulence import DrydenVertical

__all__ = [
    "G0",
    "MAX_INPUT_AMPLITUDE",
    "T2_TRUE",
    "T2_MODELS",
    "SIGNALS",
    "RESPONSES",
    "BAND_LIMITED_ON",
    "SimulationConfig",
    "ShortPeriodRecord",
    "standard_atmosphere_density",
    "simulate_short_period",
    "add_noise",
    "reduce_short_period",
    "SensorStreams",
    "simulate_sensor_streams",
    "gust_velocity",
    "state_space",
    "gust_input",
    "FineResponse",
    "fine_response",
    "StreamRates",
    "sensor_streams",
    "simulate_maneuver",
    "campaign_seeds",
    "simulate_campaign",
]

FloatArray = npt.NDArray[np.float64]
Stamps = npt.NDArray[np.int64]

G0 = 9.80665
FT = 0.3048

# Table 3 true values.
T2_TRUE = {"CZ_alpha": -3.911, "CZ_delta_e": 0.215, "Cm_alpha": -1.481, "Cm_q": -53.25, "Cm_delta_e": -1.830}
T2_MODELS = (
    ModelConfig("CZ", ("1", "alpha", "delta_e")),
    ModelConfig("Cm", ("1", "alpha", "q_hat", "delta_e")),
)
SIGNALS = ("delta_e", "alpha", "q", "az")
RESPONSES = ("alpha", "q", "az")  # the measured responses: every signal but the elevator
# The signals that carry the band-limited noise by default: the measured responses, whose
# Table 3 means lie closer to the paper's (docs/validation.md, "Which signals carry the
# band-limited noise"; docs/studies/table3_noise_variant).
BAND_LIMITED_ON: tuple[str, ...] = RESPONSES
Seed = int | np.random.SeedSequence
# Spawn-key tag of a maneuver's gust generator (its noise generator is the seed's own stream).
_GUST_KEY = 0x67757374


def standard_atmosphere_density(altitude_m: float) -> float:
    """ISA troposphere density (kg/m^3)."""
    T = 288.15 - 0.0065 * altitude_m
    return float(1.225 * (T / 288.15) ** (G0 / (287.05287 * 0.0065) - 1.0))


@dataclass(frozen=True)
class SimulationConfig:
    airspeed: float = 134.0 * FT  # m/s
    altitude: float = 1370.0 * FT  # m
    alpha_trim: float = np.deg2rad(4.8)
    delta_e_trim: float = 0.0
    rate: float = 50.0  # Hz, measurements
    duration: float = 12.0  # s
    input_start: float = 0.5  # s
    sample_offset: float = 0.0  # s, first measurement time (a multiple of 1/fine_rate)
    fine_rate: float = 1000.0  # Hz, integration grid
    snr: dict[str, float] = field(default_factory=lambda: {"delta_e": 40.0, "alpha": 12.0, "q": 30.0, "az": 40.0})
    band_limit_hz: float = 2.0
    chebyshev_ripple_db: float = 0.5
    true: dict[str, float] = field(default_factory=lambda: dict(T2_TRUE))

    @property
    def density(self) -> float:
        return standard_atmosphere_density(self.altitude)

    @property
    def qbar(self) -> float:
        return 0.5 * self.density * self.airspeed**2


@dataclass
class ShortPeriodRecord:
    """Sampled signals (aircraft body axes, SI): time, elevator, alpha, q, a_z; constants V and
    qbar; ``noise_free`` holds the same signals without noise; ``noise_scale`` the RMS
    variation of each signal in calm air, the unit of :func:`add_noise`'s noise levels;
    ``gust`` the vertical gust ``w_g`` (m/s, positive up) at the sample times, ``None`` in
    calm air."""

    t: FloatArray
    delta_e: FloatArray
    alpha: FloatArray
    q: FloatArray
    az: FloatArray
    V: float
    qbar: float
    aircraft: AircraftConfig
    config: SimulationConfig
    noise_free: dict[str, FloatArray] = field(default_factory=dict)
    noise_scale: dict[str, float] = field(default_factory=dict)
    gust: FloatArray | None = None

    def signals(self) -> dict[str, FloatArray]:
        return {name: getattr(self, name) for name in SIGNALS}


def state_space(
    cfg: SimulationConfig, ac: AircraftConfig
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Eq. 25a-b: states (d alpha, d q), input d delta_e, outputs (d alpha, d q, d a_z m/s^2)."""
    tv = cfg.true
    V, qS = cfg.airspeed, cfg.qbar * ac.S
    za = qS / (ac.mass * V)
    mq = qS * ac.cbar / ac.Iyy
    A = np.array([[za * tv["CZ_alpha"], 1.0], [mq * tv["Cm_alpha"], mq * ac.cbar / (2 * V) * tv["Cm_q"]]])
    B = np.array([[za * tv["CZ_delta_e"]], [mq * tv["Cm_delta_e"]]])
    # Eq. 25b gives a_z in g; times g: a_z = qbar S / m (CZ_alpha alpha + CZ_de de) in m/s^2.
    C = np.array([[1.0, 0.0], [0.0, 1.0], [qS / ac.mass * tv["CZ_alpha"], 0.0]])
    Dm = np.array([[0.0], [0.0], [qS / ac.mass * tv["CZ_delta_e"]]])
    return A, B, C, Dm


def gust_input(cfg: SimulationConfig, ac: AircraftConfig) -> tuple[FloatArray, FloatArray]:
    """Input and feedthrough columns of the gust angle ``w_g / V`` (module docstring): it
    acts through C_Z_alpha and C_m_alpha like alpha, and the vane and a_z read it."""
    tv = cfg.true
    V, qS = cfg.airspeed, cfg.qbar * ac.S
    za = qS / (ac.mass * V)
    mq = qS * ac.cbar / ac.Iyy
    Bg = np.array([[za * tv["CZ_alpha"]], [mq * tv["Cm_alpha"]]])
    Dg = np.array([[1.0], [0.0], [qS / ac.mass * tv["CZ_alpha"]]])
    return Bg, Dg


def _rms_variation(x: FloatArray) -> float:
    return float(np.sqrt(np.mean((x - x.mean()) ** 2)))


@dataclass(frozen=True)
class FineResponse:
    """The response on the integration grid: elevator ``u``, calm-air outputs ``y`` (d alpha,
    q, d a_z of Eq. 25b), the gust ``w_g`` and its outputs ``y_gust`` (``None`` in calm air)."""

    t: FloatArray
    u: FloatArray
    y: FloatArray
    gust: FloatArray | None
    y_gust: FloatArray | None


def fine_response(
    cfg: SimulationConfig, ac: AircraftConfig, elevator: Multisine, gust: FloatArray | None
) -> FineResponse:
    A, B, C, Dm = state_space(cfg, ac)
    n_fine = int(round(cfg.duration * cfg.fine_rate))
    t_fine = np.arange(n_fine) / cfg.fine_rate
    tau = t_fine - cfg.input_start
    on = (tau >= 0) & (tau <= elevator.period)
    u = np.where(on, elevator(np.clip(tau, 0, elevator.period)), 0.0)
    _, y, _ = signal.lsim((A, B, C, Dm), u, t_fine)
    if gust is None:
        return FineResponse(t_fine, u, y, None, None)
    gust = np.asarray(gust, dtype=np.float64)
    if gust.shape != (n_fine,) or not np.isfinite(gust).all():
        raise ConfigError(f"gust must be {n_fine} finite samples of w_g on the {cfg.fine_rate:g} Hz "
                          f"integration grid, got shape {gust.shape}")
    Bg, Dg = gust_input(cfg, ac)
    _, y_gust, _ = signal.lsim((A, Bg, C, Dg), gust / cfg.airspeed, t_fine)
    return FineResponse(t_fine, u, y, gust, y_gust)


def _sampled(response: FineResponse, cfg: SimulationConfig, ac: AircraftConfig) -> ShortPeriodRecord:
    """The record at ``cfg.rate`` from ``cfg.sample_offset`` on."""
    step = int(round(cfg.fine_rate / cfg.rate))
    idx = np.arange(int(round(cfg.sample_offset * cfg.fine_rate)), response.t.size, step)
    u, y = response.u, response.y
    ct = np.cos(cfg.alpha_trim)
    # Trim: level flight, so the body-z specific force balances gravity (a_z = -g cos(theta),
    # with theta = alpha in level flight) plus the perturbation of Eq. 25b.
    clean = {
        "delta_e": cfg.delta_e_trim + u[idx],
        "alpha": cfg.alpha_trim + y[idx, 0],
        "q": y[idx, 1],
        "az": -G0 * ct + y[idx, 2],
    }
    scale = {k: _rms_variation(v) for k, v in clean.items()}
    if response.y_gust is not None:
        for i, name in enumerate(RESPONSES):
            clean[name] = clean[name] + response.y_gust[idx, i]
    return ShortPeriodRecord(
        t=response.t[idx], V=cfg.airspeed, qbar=cfg.qbar, aircraft=ac, config=cfg,
        noise_free={k: v.copy() for k, v in clean.items()}, noise_scale=scale,
        gust=None if response.gust is None else response.gust[idx], **clean,
    )


def simulate_short_period(
    cfg: SimulationConfig = SimulationConfig(),
    aircraft: AircraftConfig | None = None,
    elevator: Multisine = T2_TABLE2["elevator"],
    *,
    gust: FloatArray | None = None,
) -> ShortPeriodRecord:
    """Noise-free T-2 short-period response to the elevator multisine, sampled at ``cfg.rate``.

    ``gust``: the vertical gust ``w_g`` (m/s, positive up) on the integration grid
    (``cfg.duration * cfg.fine_rate`` samples from t = 0, :func:`gust_velocity`), or ``None``
    for calm air. Its response (module docstring) is added to the calm-air response.
    """
    ac = aircraft or load_aircraft("t2")
    return _sampled(fine_response(cfg, ac, elevator, gust), cfg, ac)


def _check_band_limited_on(band_limited_on: Collection[str]) -> frozenset[str]:
    chosen = frozenset(band_limited_on)
    if isinstance(band_limited_on, str) or not chosen <= set(SIGNALS):
        raise ConfigError(f"band_limited_on must be a collection of signal names from {SIGNALS}, "
                          f"got {band_limited_on!r}")
    return chosen


def add_noise(
    record: ShortPeriodRecord,
    band_level: float,
    rng: np.random.Generator,
    *,
    band_limited_on: Collection[str] = BAND_LIMITED_ON,
) -> ShortPeriodRecord:
    """A copy of ``record`` with the Section IV.A noise: wide-band noise at the configured SNRs
    on every signal, and band-limited noise at ``band_level`` (fraction, e.g. 0.2) of each
    signal's RMS variation (``record.noise_scale``) on the signals named in
    ``band_limited_on``: :data:`BAND_LIMITED_ON` by default, the measured responses
    (:data:`RESPONSES`: alpha, q and a_z, not the measured elevator), whose Table 3 means lie
    closer to the paper's; or all four (:data:`SIGNALS`, the section's "added to the
    measurements" read as every measurement; docs/validation.md,
    docs/studies/table3_noise_variant). The random numbers drawn do not depend on
    ``band_limited_on``: the variants differ only by the band-limited noise left out."""
    chosen = _check_band_limited_on(band_limited_on)
    cfg = record.config
    n = record.t.size
    b, a = signal.cheby1(5, cfg.chebyshev_ripple_db, cfg.band_limit_hz, fs=cfg.rate)
    warm = 10 * int(cfg.rate)  # let the filter reach its stationary state
    noisy = {}
    for name in SIGNALS:
        clean = record.noise_free[name]
        rms = record.noise_scale[name] if record.noise_scale else _rms_variation(clean)
        wide = rng.standard_normal(n) * rms / cfg.snr[name]
        white = rng.standard_normal(n + warm)
        if name not in chosen:
            noisy[name] = clean + wide
            continue
        colored = signal.lfilter(b, a, white)[warm:]
        colored *= band_level * rms / np.sqrt(np.mean(colored**2))
        noisy[name] = clean + wide + colored
    return ShortPeriodRecord(
        t=record.t, V=record.V, qbar=record.qbar, aircraft=record.aircraft, config=cfg,
        noise_free=record.noise_free, noise_scale=record.noise_scale, gust=record.gust, **noisy,
    )


def reduce_short_period(
    record: ShortPeriodRecord, diff: DifferentiatorConfig = DifferentiatorConfig()
) -> tuple[FloatArray, dict[str, tuple[FloatArray, FloatArray]]]:
    """Eq. 1 and Eq. 2 for the two short-period models, through the same aero reduction and
    fixed-lag differentiator the node uses.

    Returns ``(t, {"CZ": (X, z), "Cm": (X, z)})`` on the samples where the differentiated
    pitch rate exists (the first ``window-1-lag`` and last ``lag`` samples are dropped, all
    signals aligned).
    """
    dt = 1.0 / record.config.rate
    q_dot = differentiate(record.q, dt, diff)
    keep = np.isfinite(q_dot)
    zeros = np.zeros(int(keep.sum()))
    state = FlightState(
        ax=zeros, ay=zeros, az=record.az[keep], p=zeros, q=record.q[keep], r=zeros,
        p_dot=zeros, q_dot=q_dot[keep], r_dot=zeros, V=np.full(zeros.shape, record.V),
        alpha=record.alpha[keep], beta=zeros, qbar=np.full(zeros.shape, record.qbar),
        delta_e=record.delta_e[keep],
    )
    coef = coefficients(state, record.aircraft)
    values = regressors(state, record.aircraft)
    # Array states give array coefficients (aero.Signal is float | FloatArray).
    out = {m.output: (regressor_matrix(m, values), np.asarray(coef[m.output], dtype=np.float64)) for m in T2_MODELS}
    return record.t[keep], out


@dataclass(frozen=True)
class SensorStreams:
    """The T-2 maneuver as the node's input streams (REP-103 body frame, SI): per stream,
    integer-nanosecond stamps and a value array. ``surface_names`` label the surface columns."""

    start_ns: int
    imu: tuple[Stamps, FloatArray]  # (stamps, (N, 6): angular velocity xyz, specific force xyz)
    airspeed: tuple[Stamps, FloatArray]  # (stamps, (N, 3))
    dynamic_pressure: tuple[Stamps, FloatArray]  # (stamps, (N,))
    control_surfaces: tuple[Stamps, FloatArray]  # (stamps, (N, 5))
    thrust: tuple[Stamps, FloatArray]  # (stamps, (N,))
    surface_names: tuple[str, ...] = ("elevator_left", "elevator_right", "aileron_left", "aileron_right", "rudder")


def gust_velocity(
    gust: DrydenVertical, rng: np.random.Generator, cfg: SimulationConfig = SimulationConfig()
) -> FloatArray:
    """The vertical gust ``w_g`` (m/s) met at ``cfg.airspeed`` on the integration grid of
    :func:`simulate_short_period` (``cfg.fine_rate``, stationary from t = 0)."""
    n_fine = int(round(cfg.duration * cfg.fine_rate))
    return gust.sample(n_fine, cfg.airspeed, 1.0 / cfg.fine_rate, rng)


def _draws(
    seed: Seed, gust: DrydenVertical | None, cfg: SimulationConfig
) -> tuple[np.random.Generator, FloatArray | None]:
    """A maneuver's noise generator, ``default_rng(seed)`` as in calm air, and its gust on the
    integration grid (``None`` in calm air), drawn from a child stream of the seed, so the
    noise does not depend on the gust."""
    ss = seed if isinstance(seed, np.random.SeedSequence) else np.random.SeedSequence(seed)
    if gust is None or gust.sigma == 0.0:
        return np.random.default_rng(ss), None
    gust_ss = np.random.SeedSequence(ss.entropy, spawn_key=(*ss.spawn_key, _GUST_KEY), pool_size=ss.pool_size)
    return np.random.default_rng(ss), gust_velocity(gust, np.random.default_rng(gust_ss), cfg)


def simulate_maneuver(
    band_level: float = 0.2,
    seed: Seed = 250,
    *,
    gust: DrydenVertical | None = None,
    band_limited_on: Collection[str] = BAND_LIMITED_ON,
    cfg: SimulationConfig = SimulationConfig(),
) -> ShortPeriodRecord:
    """One seeded T-2 maneuver at ``cfg.rate`` (Section IV.A, Eq. 25), in turbulence when
    ``gust`` is given (its ``sigma`` 0 or ``None``: calm air), with the :func:`add_noise`
    noise. The noise comes from ``np.random.default_rng(seed)``, the gust from an independent
    child stream of ``seed``; in calm air this is ``add_noise(simulate_short_period(cfg),
    band_level, np.random.default_rng(seed))``."""
    rng, w = _draws(seed, gust, cfg)
    return add_noise(simulate_short_period(cfg, gust=w), band_level, rng, band_limited_on=band_limited_on)


def simulate_sensor_streams(
    band_level: float = 0.2,
    seed: Seed = 250,
    *,
    imu_rate: float = 200.0,
    air_data_rate: float = 50.0,
    surface_rate: float = 100.0,
    thrust_rate: float = 10.0,
    air_data_offset: float = 0.004,
    surface_offset: float = 0.002,
    start_ns: int = 1_767_225_600 * 10**9,
    cfg: SimulationConfig = SimulationConfig(),
    gust: DrydenVertical | None = None,
    band_limited_on: Collection[str] = BAND_LIMITED_ON,
    input_amplitude: float = 1.0,
) -> SensorStreams:
    """One seeded T-2 maneuver (Section IV.A, Eq. 25) at realistic sensor rates.

    Each stream is sampled from the same 1 kHz simulation at its own rate and offset and
    gets the paper's noise (wide-band at the Section IV.A SNRs plus band-limited noise at
    ``band_level`` on ``band_limited_on``, :func:`add_noise`) generated at that rate: the IMU
    carries q and a_z, the air data alpha (as the airspeed vector), the surfaces the elevator
    (both halves equal, Eq. 23). With ``gust`` every stream sees the same gust (one draw on
    the integration grid), the air data the aerodynamic alpha. Generators as in
    :func:`simulate_maneuver`. Trim is level flight: specific force (g sin alpha, 0, -g cos
    alpha) in aircraft axes.

    ``input_amplitude``: the elevator multisine at this fraction of Table 2's amplitude (0: no
    maneuver, the elevator held at trim). Every signal's noise stays at the scale of the
    nominal maneuver (Table 2's amplitude, calm air): the noise belongs to the sensors, so with
    0 the elevator still shows its sensor noise. 1 is the nominal maneuver, bit for bit.
    """
    if not 0.0 <= input_amplitude <= MAX_INPUT_AMPLITUDE:  # (NaN too)
        raise ConfigError(f"input_amplitude must be a number in [0, {MAX_INPUT_AMPLITUDE:g}], got {input_amplitude!r}")
    rng, w = _draws(seed, gust, cfg)
    ac = load_aircraft("t2")
    elevator = T2_TABLE2["elevator"]
    nominal = None
    if input_amplitude != 1.0:
        nominal = fine_response(cfg, ac, elevator, None)  # the noise scale: Table 2's maneuver, calm air
        elevator = replace(elevator, amplitude=elevator.amplitude * float(input_amplitude))
    response = fine_response(cfg, ac, elevator, w)
    rates = StreamRates(imu_rate, air_data_rate, surface_rate, thrust_rate, air_data_offset, surface_offset)
    return sensor_streams(response, nominal, cfg, ac, rng, band_level=band_level, band_limited_on=band_limited_on,
                          rates=rates, start_ns=start_ns)


@dataclass(frozen=True)
class StreamRates:
    """The sensors' rates (Hz) and the offsets (s) of the air data and surface samples."""

    imu: float = 200.0
    air_data: float = 50.0
    surface: float = 100.0
    thrust: float = 10.0
    air_data_offset: float = 0.004
    surface_offset: float = 0.002


def sensor_streams(
    response: FineResponse,
    nominal: FineResponse | None,
    cfg: SimulationConfig,
    ac: AircraftConfig,
    rng: np.random.Generator,
    *,
    band_level: float,
    band_limited_on: Collection[str],
    rates: StreamRates = StreamRates(),
    start_ns: int,
) -> SensorStreams:
    """A simulated response (:func:`fine_response`) as the node's input streams, each sampled
    at its rate with :func:`add_noise`'s noise drawn from ``rng`` (IMU, air data, surfaces in
    that order) at the scale of ``nominal``'s response (``None``: the response's own); the
    stamps count from ``start_ns``. :func:`simulate_sensor_streams` says what each stream holds."""
    imu_rate, air_data_rate, surface_rate = rates.imu, rates.air_data, rates.surface
    thrust_rate, air_data_offset, surface_offset = rates.thrust, rates.air_data_offset, rates.surface_offset

    def stream(rate: float, offset: float) -> tuple[Stamps, ShortPeriodRecord]:
        at = replace(cfg, rate=rate, sample_offset=offset)
        rec = _sampled(response, at, ac)
        if nominal is not None:
            rec.noise_scale = _sampled(nominal, at, ac).noise_scale
        noisy = add_noise(rec, band_level, rng, band_limited_on=band_limited_on)
        stamps = start_ns + np.round(rec.t * 1e9).astype(np.int64)
        return stamps, noisy

    t_imu, imu = stream(imu_rate, 0.0)
    n = t_imu.size
    ax = G0 * np.sin(cfg.alpha_trim)
    # REP-103 = aircraft axes with y and z negated.
    gyro = np.column_stack([np.zeros(n), -imu.q, np.zeros(n)])
    accel = np.column_stack([np.full(n, ax), np.zeros(n), -imu.az])
    t_air, air = stream(air_data_rate, air_data_offset)
    V = cfg.airspeed
    vel = np.column_stack([V * np.cos(air.alpha), np.zeros(t_air.size), -V * np.sin(air.alpha)])
    qbar = np.full(t_air.size, cfg.qbar)
    t_srf, srf = stream(surface_rate, surface_offset)
    zeros = np.zeros(t_srf.size)
    surfaces = np.column_stack([srf.delta_e, srf.delta_e, zeros, zeros, zeros])
    n_thr = int(np.ceil(cfg.duration * thrust_rate - 1e-6))  # the samples before cfg.duration
    t_thr = start_ns + np.round(np.arange(n_thr) / thrust_rate * 1e9).astype(np.int64)
    # Thrust balancing a drag coefficient of 0.03 at trim (CX only; the T-2 model has no CX).
    thrust = np.full(t_thr.size, ac.mass * ax + 0.03 * cfg.qbar * ac.S)
    return SensorStreams(
        start_ns=start_ns,
        imu=(t_imu, np.column_stack([gyro, accel])),
        airspeed=(t_air, vel),
        dynamic_pressure=(t_air, qbar),
        control_surfaces=(t_srf, surfaces),
        thrust=(t_thr, thrust),
    )


def campaign_seeds(seed: int, maneuvers: int) -> list[np.random.SeedSequence]:
    """The seeds of a campaign's maneuvers: ``SeedSequence(seed).spawn(maneuvers)``, so
    maneuver ``i`` is the same in every campaign of that seed, whatever its length."""
    if maneuvers < 0:
        raise ConfigError(f"maneuvers must be an integer >= 0, got {maneuvers!r}")
    return np.random.SeedSequence(seed).spawn(maneuvers)


def simulate_campaign(
    maneuvers: int,
    gust: DrydenVertical | None,
    *,
    seed: int = 2010,
    band_level: float = 0.2,
    band_limited_on: Collection[str] = BAND_LIMITED_ON,
    cfg: SimulationConfig = SimulationConfig(),
    input_amplitude: float = 1.0,
) -> Iterator[SensorStreams]:
    """``maneuvers`` repeated T-2 maneuvers in the same turbulence (Section IV.B's flight-test
    campaign, simulated), one at a time (memory stays that of one maneuver):
    :func:`simulate_sensor_streams` of each of :func:`campaign_seeds`, every maneuver with its
    own gust and noise sequences; ``input_amplitude`` as there."""
    for s in campaign_seeds(seed, maneuvers):
        yield simulate_sensor_streams(band_level, s, cfg=cfg, gust=gust, band_limited_on=band_limited_on,
                                      input_amplitude=input_amplitude)

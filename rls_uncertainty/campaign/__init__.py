"""Flight-test campaigns: many maneuvers into the paper's Table 4 and Fig. 12 (Section IV.B).

``rls-uncertainty campaign INPUT... --config CFG --out DIR`` (docs/campaign.md). Each maneuver
(:mod:`.maneuvers`: replay bags, or spans of one recording) runs through the replay's pipeline
with the configured lags and, on the same regression rows, with all lags (:mod:`.run`), in
local worker processes or on a Dask cluster (:mod:`..executors`); the results, in maneuver
order, make Table 4 (:mod:`.table4`) and Fig. 12 (:mod:`.figure`). Written to ``--out``:
``maneuvers.csv``, ``table4.csv``, ``table4.md``, ``summary.txt``, ``fig12_<model>.png`` and
``models.json`` (each maneuver's final models with their covariances, :mod:`..offline.model_file`,
for ``rls-uncertainty predict``).
With ``estimator.method`` ``frequency`` or ``both`` every file shows the frequency-domain
estimates too, in rows (or bars) of their own beside the time-domain ones (``method``).
"""

from __future__ import annotations

import time
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from ..datapath.config import PipelineConfig
from ..executors import Executor, LocalProcesses, Lost
from ..files import input_problem, output_directory
from ..offline.bags import check_bag
from ..offline.figures import FigureOptions
from ..offline.model_file import MODELS_FILE, models_json
from ..progress import Progress
from .figure import campaign_figures
from .maneuvers import Maneuver, from_bags, load_maneuvers
from .run import MANEUVER_COLUMNS, CampaignSettings, ManeuverResult, ParameterResult, failed_result, run_maneuver
from .table4 import TABLE4_COLUMNS, Table4Row, maneuvers_csv, summary_text, table4, table4_csv, table4_markdown

__all__ = [
    "Maneuver",
    "from_bags",
    "load_maneuvers",
    "CampaignSettings",
    "ParameterResult",
    "ManeuverResult",
    "MANEUVER_COLUMNS",
    "Table4Row",
    "TABLE4_COLUMNS",
    "CampaignResult",
    "run_campaign",
    "write_campaign",
    "campaign_to",
]

DEFAULT_FIGURES = FigureOptions()  # PNG at figures.DEFAULT_DPI


@dataclass
class CampaignResult:
    """A campaign's maneuvers (in order), its Table 4, the executor that ran it, and the wall
    times (s) of running the maneuvers and of writing the outputs."""

    results: list[ManeuverResult]
    table: list[Table4Row]
    settings: CampaignSettings
    executor: str = ""
    wall_seconds: float = 0.0
    write_seconds: float = 0.0
    written: dict[str, Path] = field(default_factory=dict)
    # Lines the summary ends with (a recording cut into maneuvers: the events it refused).
    notes: tuple[str, ...] = ()

    @property
    def per_minute(self) -> float:
        """Maneuvers per minute of wall time, running and writing."""
        wall = self.wall_seconds + self.write_seconds
        return 60.0 * len(self.results) / wall if wall > 0 else float("inf")

    def seconds(self) -> dict[str, float]:
        """Where the workers' time went, summed over the maneuvers (``read``, ``pipeline``,
        ``all_lags``)."""
        total: dict[str, float] = {}
        for res in self.results:
            for key, s in res.seconds.items():
                total[key] = total.get(key, 0.0) + s
        return total

    def summary(self) -> str:
        """The printed summary (``summary.txt``)."""
        text = summary_text(self.table, self.results, _lags(self.settings.config))
        return text + "".join(f"{note}\n" for note in self.notes)


def _lags(config: PipelineConfig) -> object:
    """The lags behind the corrected standard errors the tables name: the time domain's
    (Eq. 22), or with only the frequency-domain estimates theirs (``frequency.lag_span``)."""
    if config.publishes_time or config.frequency is None:
        return config.estimator.lags
    return config.frequency.n_lags


def run_campaign(maneuvers: Sequence[Maneuver], settings: CampaignSettings, executor: Executor | None = None, *,
                 progress: bool | None = False) -> CampaignResult:
    """Every maneuver on ``executor`` (default: every local core), then Table 4 over them in
    their order. A maneuver no worker finished is reported as ``failed: <why>``. ``progress``:
    a bar of the maneuvers done on stderr (:mod:`..progress`)."""
    executor = executor or LocalProcesses()
    t0 = time.perf_counter()
    with Progress(len(maneuvers), "campaign", " maneuvers", progress) as bar:
        done = executor.run(run_maneuver, [(m, settings) for m in maneuvers], lambda n, _total: bar.set_to(n))
    results = [failed_result(m.name, settings.config, f"failed: {r.why}") if isinstance(r, Lost) else r
               for m, r in zip(maneuvers, done, strict=True)]
    wall = time.perf_counter() - t0
    return CampaignResult(results, table4(results), settings, executor.description, wall)


def write_campaign(campaign: CampaignResult, out: Path, *, figures: FigureOptions | None = DEFAULT_FIGURES,
                   progress: bool | None = False) -> dict[str, Path]:
    """The campaign's files into the directory ``out`` (module docstring); the Fig. 12 plots in
    the ``figures`` formats (None: none), with a bar on stderr per ``progress``."""
    config = campaign.settings.config
    lags = _lags(config)
    texts = {
        "maneuvers": ("maneuvers.csv", maneuvers_csv(campaign.results)),
        "table4_csv": ("table4.csv", table4_csv(campaign.table)),
        "table4_md": ("table4.md", table4_markdown(campaign.table, campaign.results, lags)),
        "summary": ("summary.txt", campaign.summary()),
        "models": (MODELS_FILE, models_json([(r.name, r.models) for r in campaign.results])),
    }
    paths = {}
    for key, (name, text) in texts.items():
        paths[key] = out / name
        paths[key].write_text(text)
    if figures is not None:
        frequency_lags = f"{config.frequency.n_lags} lags" if config.frequency is not None else ""
        for path in campaign_figures(out, campaign.table, campaign.results, formats=figures.formats, dpi=figures.dpi,
                                     lags=f"{lags} lags", frequency_lags=frequency_lags, progress=progress):
            paths[path.stem] = path
    return paths


def campaign_to(out: str | Path, maneuvers: Sequence[Maneuver], settings: CampaignSettings,
                executor: Executor | None = None, *, progress: bool | None = False,
                figures: FigureOptions | None = DEFAULT_FIGURES, force: bool = False,
                inputs: Iterable[str | Path] = ()) -> CampaignResult:
    """:func:`run_campaign` written to ``out`` (:func:`.files.output_directory`: checked
    before the first maneuver runs, complete or absent; never over an input bag or ``inputs``).
    An input that is not a regular file or a directory is a :class:`.errors.BagError` before
    anything runs (:func:`.offline.bags.check_bag`)."""
    bags = sorted({m.bag for m in maneuvers})
    for bag in bags:
        # A FIFO, a device or a symbolic link loop is refused before anything runs; a missing
        # bag fails its maneuver alone (``failed: ... no such bag``), the others still count.
        if input_problem(bag) != "no such file or directory":
            check_bag(bag)
    with output_directory(out, force=force, inputs=(*bags, *inputs)) as tmp:
        campaign = run_campaign(maneuvers, settings, executor, progress=progress)
        t0 = time.perf_counter()
        written = write_campaign(campaign, tmp, figures=figures, progress=progress)
        campaign.written = {k: Path(out) / p.relative_to(tmp) for k, p in written.items()}
        campaign.write_seconds = time.perf_counter() - t0
    return campaign

"""What the studies' tables share: numbers, medians, shares with their interval, and
the runs of a group."""

from __future__ import annotations

import math
import statistics
from collections.abc import Iterable, Mapping, Sequence
from typing import Any

from deploy.analysis import effects
from deploy.analysis.wilson import interval, share, wilson

VERDICTS = ("correct", "wrong", "split", "undecided")
# How a time comparison names the runs it needs (``compare_times``' ``what``).
CONSENSUS_RUNS = ("run with consensus", "runs with consensus")


def number(value: float | None, digits: int = 0) -> str:
    """A number to ``digits`` places; ``-`` for none."""
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "-"
    return f"{value:.{digits}f}"


def runs(count: int) -> str:
    """``1 run``, ``5 runs``."""
    return f"{count} run" if count == 1 else f"{count} runs"


def seeds(numbers: list[int]) -> str:
    """``seed 3``, ``seeds 0-9``, ``seeds 0, 2``."""
    if len(numbers) == 1:
        return f"seed {numbers[0]}"
    if numbers == list(range(numbers[0], numbers[-1] + 1)):
        return f"seeds {numbers[0]}-{numbers[-1]}"
    return "seeds " + ", ".join(map(str, numbers))


def median(values: Iterable[float]) -> float | None:
    found = list(values)
    return statistics.median(found) if found else None


def mean(values: Iterable[float]) -> float | None:
    found = list(values)
    return statistics.fmean(found) if found else None


def result(record: dict[str, Any]) -> dict[str, Any]:
    found: dict[str, Any] = record["result"]
    return found


def count(records: Sequence[dict[str, Any]], verdict: str) -> int:
    return sum(result(record)["verdict"] == verdict for record in records)


def counted(count: int, total: int) -> str:
    """``3 (1-8%)``: a count of a row's runs (its number of runs in another column) and the
    95% interval of its share; ``-`` for no runs."""
    return "-" if total == 0 else f"{count} ({interval(count, total)})"


def compare_times(
    treated: Mapping[int, float] | Sequence[float],
    baseline: Mapping[int, float] | Sequence[float],
    what: tuple[str, str] = ("right run", "right runs"),
) -> str:
    """``1.18 (0.95-1.43)``: the ratio of the median times, ``treated`` over ``baseline``,
    and its 95% bootstrap interval: times by seed (runs paired by seed, the seeds
    resampled) or lists (unpaired, each resampled on its own). With too few runs
    (``what``: the words for one and for several), says that no time can be compared."""
    if isinstance(treated, Mapping) and isinstance(baseline, Mapping):
        found = effects.paired_median_ratio(treated, baseline)
    else:
        found = effects.median_ratio(list(_values(treated)), list(_values(baseline)))
    if found is not None:
        return effects.estimate_text(found)
    if len(treated) < effects.MIN_RUNS:
        return f"no time to compare ({counting(len(treated), *what)})"
    return f"no time to compare (the baseline: {counting(len(baseline), *what)})"


def _values(times: Mapping[int, float] | Sequence[float]) -> Iterable[float]:
    return times.values() if isinstance(times, Mapping) else times


def counting(count: int, one: str, several: str) -> str:
    """``1 right run``, ``2 right runs``."""
    return f"{count} {one if count == 1 else several}"


def correct_share(records: Sequence[dict[str, Any]]) -> str:
    """``7/10 (39-90%)``: the runs whose (honest) robots all chose the best site."""
    return share(count(records, "correct"), len(records))


def error_bar(successes: int, trials: int) -> tuple[float, float, float]:
    """The share and the distances below and above it to its 95% interval, for a plot."""
    if trials == 0:
        return math.nan, 0.0, 0.0
    low, high = wilson(successes, trials)
    value = successes / trials
    return value, value - low, high - value


def groups(
    records: Sequence[dict[str, Any]], *names: str
) -> dict[tuple[Any, ...], list[dict[str, Any]]]:
    """The records by the values of these parameters, in the order first met."""
    found: dict[tuple[Any, ...], list[dict[str, Any]]] = {}
    for record in records:
        found.setdefault(tuple(record["params"][name] for name in names), []).append(record)
    return found


def median_bar(values: Sequence[float]) -> tuple[float, float, float]:
    """The median and the distances below and above it to its 95% bootstrap interval, for
    a plot (nan without enough runs for an interval, the median alone with too few)."""
    found = effects.median_interval(values)
    if found is None:
        return (statistics.median(values) if values else math.nan), 0.0, 0.0
    return found.value, found.value - found.low, found.high - found.value


def plot_bars(
    axis: Any, xs: Sequence[float], bars: Sequence[tuple[float, float, float]], **style: Any
) -> None:
    """Points with their intervals: ``bars`` as ``error_bar`` and ``median_bar`` give them
    (a value and the distances below and above it), ``style`` as matplotlib's errorbar
    takes it."""
    axis.errorbar(
        xs,
        [bar[0] for bar in bars],
        yerr=[[bar[1] for bar in bars], [bar[2] for bar in bars]],
        **style,
    )


def pyplot() -> Any:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def no_runs_yet(axis: Any) -> None:
    """Mark an empty panel of a figure: its runs are not made yet."""
    axis.text(0.5, 0.5, "no runs yet", ha="center", va="center", transform=axis.transAxes)

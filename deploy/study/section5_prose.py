"""The numbers docs/section5.md's text reads from the settings study's runs ("Why the last
robot lags", "The settings the paper leaves open", "The goal"), checked against them
(``prose.Claim``); the text of the sections above them reads ``swarm section5``'s runs and
is checked by ``section5_tables.claims``."""

from __future__ import annotations

import statistics
from typing import Any

from deploy.analysis import effects
from deploy.analysis.prose import Claim, fixed
from deploy.study import section5_settings_runs as study
from deploy.study import tables
from deploy.study.declare import Records

N5, N8, N10 = study.SITES


def _rows(records: Records, setting: str) -> dict[int, dict[str, Any]]:
    return {
        n: study.row(runs, n)
        for n in study.SITES
        if (runs := records.where(setting=setting, sites=n))
    }


def _percent(count: int, total: int) -> str:
    return f"{100 * count / total:.0f}"


def _span(values: list[float], digits: int) -> tuple[str, str]:
    return fixed(min(values), digits), fixed(max(values), digits)


def claims(records: Records) -> list[Claim]:
    rows = {setting: _rows(records, setting) for setting in study.SETTINGS}
    if any(len(found) < len(study.SITES) for found in rows.values()):
        return []  # the study is not made yet: its text is not read from it
    return [*_lag(records), *_settings(records, rows), *_goal(records, rows)]


def _lag(records: Records) -> list[Claim]:
    summaries = study.lag_summaries(records)
    by_n = {summary["n"]: summary for summary in summaries}
    last = [summary["last_pool_mean"] for summary in summaries]
    others = [summary["other_pool_mean"] for summary in summaries]
    last_alone = [100 * summary["last_alone"] for summary in summaries]
    other_alone = [100 * summary["other_alone"] for summary in summaries]
    at_nest = [100 * summary["last_phases"].get("at the nest", 0.0) for summary in summaries]
    at_site = [
        100 * summary["last_phases"].get("at or going to a site", 0.0) for summary in summaries
    ]

    def first(n: int, key: str) -> str:
        return fixed(by_n[n][key][1], 1)

    after_first = [summary["undecided_missing"][1] for summary in summaries]
    last_left = [
        summary["undecided_missing"][max(summary["undecided_missing"])] for summary in summaries
    ]
    lone = [summary["runs_with_lone_finish"] for summary in summaries]
    trips = [summary["trips_after_others_mean"] for summary in summaries]
    return [
        Claim(
            "Its pools average {} to {} opinions against about {} for the other robots, and it "
            "pools alone in {}-{}% of its visits to the nest against {}-{}% for the others.",
            (
                *_span(last, 2),
                fixed(statistics.fmean(others), 1),
                *_span(last_alone, 0),
                *_span(other_alone, 0),
            ),
        ),
        Claim(
            "({} against {}; for n = 8, {} against {}; for n = 5, {} against {})",
            (
                first(N10, "last_pool_by_trip"),
                first(N10, "other_pool_by_trip"),
                first(N8, "last_pool_by_trip"),
                first(N8, "other_pool_by_trip"),
                first(N5, "last_pool_by_trip"),
                first(N5, "other_pool_by_trip"),
            ),
        ),
        Claim(
            "({}-{}% of those moments). {}-{}% of those moments it is at or on its way to a "
            "site, otherwise on its way back.",
            (*_span(at_nest, 0), *_span(at_site, 0)),
        ),
        Claim(
            "After the first decision, about {}-{} of the worse sites are known to be worse "
            "only to decided robots; when only the last robot is left, it still holds {} to "
            "{} worse sites possible",
            (*_span(after_first, 1), *_span(last_left, 2)),
        ),
        Claim(
            "in {}-{} runs of {} it makes at least one trip after every other robot has "
            "decided, about one more trip on average ({} to {})",
            (
                str(min(lone)),
                str(max(lone)),
                str(summaries[0]["runs"]),
                *_span(trips, 2),
            ),
        ),
    ]


def _settings(records: Records, rows: dict[str, dict[int, dict[str, Any]]]) -> list[Claim]:
    def within(setting: str, n: int) -> str:
        row = rows[setting][n]
        return _percent(row["within"], row["runs"])

    def pool(setting: str, n: int, digits: int = 2) -> str:
        return fixed(rows[setting][n]["pool_mean"], digits)

    def ratios(setting: str) -> list[effects.Estimate]:
        found = []
        for n in study.SITES:
            ratio = effects.paired_median_ratio(
                rows[setting][n]["times"], rows["default"][n]["times"]
            )
            assert ratio is not None
            found.append(ratio)
        return found

    def identical(setting: str) -> tuple[int, int]:
        base = {
            (run["params"]["sites"], run["seed"]): tables.result(run)["digest"]
            for run in records.where(setting="default")
        }
        runs = records.where(setting=setting)
        same = sum(
            base.get((run["params"]["sites"], run["seed"])) == tables.result(run)["digest"]
            for run in runs
        )
        return same, len(runs)

    quick, slow = identical("broadcast_period=0.1"), identical("broadcast_period=1")
    same = quick[0] == quick[1] and slow[0] == slow[1]
    nest = ratios("beacon_range=0.3")
    beacon = ratios("beacon_period=5")
    speed = ratios("max_wheel_speed=0.065")
    half = rows["max_wheel_speed=0.065"]
    alone = [100 * row["alone"] for row in half.values()]
    return [
        Claim(
            "for n = 10 the mean pool grows from {} to {} and the runs within n/2 from {}% to {}%",
            (
                pool("dwell=1.5", N10),
                pool("dwell=10", N10),
                within("dwell=1.5", N10),
                within("dwell=10", N10),
            ),
        ),
        Claim(
            "with a broadcast every 0.1 s, and every 1 s, all {} runs are the same, robot for "
            "robot (the same digests), as with 0.5 s"
            if same
            else "with a broadcast every 0.1 s, and every 1 s, not all {} runs are the same",
            (str(quick[1]),),
        ),
        Claim(
            "makes pools smaller ({} to {}), more robots pool alone and the swarm slower "
            "(median times {} to {} times the defaults')",
            (
                *_span([rows["beacon_period=5"][n]["pool_mean"] for n in study.SITES], 1),
                *_span([ratio.value for ratio in beacon], 2),
            ),
        ),
        Claim(
            "pools a little smaller ({} to {} against {} to {}), median times {} to {} times "
            "the defaults' (95% intervals up to {} to {}",
            (
                *_span([rows["beacon_range=0.3"][n]["pool_mean"] for n in study.SITES], 2),
                *_span([rows["default"][n]["pool_mean"] for n in study.SITES], 2),
                *_span([ratio.value for ratio in nest], 2),
                *_span([float(effects.outwards(r.low, r.high, 2).split("-")[1]) for r in nest], 2),
            ),
        ),
        Claim(
            "pools of about {}, {}-{}% of the poolings alone, and the swarm within n/2 in at "
            "most {}% of runs, its median times {} to {} times the defaults'",
            (
                fixed(statistics.fmean(row["pool_mean"] for row in half.values()), 1),
                *_span(alone, 0),
                str(max(int(within("max_wheel_speed=0.065", n)) for n in study.SITES)),
                *_span([ratio.value for ratio in speed], 2),
            ),
        ),
        Claim(
            "All {} runs at half speed reached the right consensus."
            if all(row["correct"] == row["runs"] for row in half.values())
            else "Not all {} runs at half speed reached the right consensus.",
            (str(sum(row["runs"] for row in half.values())),),
        ),
    ]


def _goal(records: Records, rows: dict[str, dict[int, dict[str, Any]]]) -> list[Claim]:
    def within(setting: str, n: int) -> str:
        row = rows[setting][n]
        return _percent(row["within"], row["runs"])

    def below(setting: str, n: int) -> str:
        row = rows[setting][n]
        return _percent(row["below"], row["runs"])

    def pool(setting: str, n: int, digits: int = 2) -> str:
        return fixed(rows[setting][n]["pool_mean"], digits)

    def over(setting: str, n: int) -> str:
        return str(rows[setting][n]["run_pool_over3"])

    ten = {
        n: study.row(
            [run for run in records.where(setting="default", sites=n) if run["seed"] < 10], n
        )
        for n in study.SITES
    }
    defaults = rows["default"]
    pools = [row["pool_mean"] for row in defaults.values()]
    overs = [row["run_pool_over3"] for row in defaults.values()]
    return [
        Claim(
            "for n = 10, {}% of runs within n/2 and {}% strictly below, with a mean pool of {} "
            "and {} runs in 100 above 3; for n = 8, {}%; for n = 5, {}% (tables above; seeds "
            "0-9 alone give {}/10, {}/10 and {}/10)",
            (
                within("default", N10),
                below("default", N10),
                pool("default", N10),
                over("default", N10),
                within("default", N8),
                within("default", N5),
                str(ten[N10]["within"]),
                str(ten[N8]["within"]),
                str(ten[N5]["within"]),
            ),
        ),
        Claim(
            "`dwell=4` reaches {}% of runs within n/2 and {}% strictly below with a mean pool "
            "of {}, and {} of its 100 runs average above 3; `dwell=4.5` reaches {}% within "
            "n/2 and {}% strictly below with a mean pool of {}, and {} of 100 runs above 3; "
            "`dwell=6` is faster still with pools of {}.",
            (
                within("dwell=4", N10),
                below("dwell=4", N10),
                pool("dwell=4", N10),
                over("dwell=4", N10),
                within("dwell=4.5", N10),
                below("dwell=4.5", N10),
                pool("dwell=4.5", N10),
                over("dwell=4.5", N10),
                pool("dwell=6", N10, 1),
            ),
        ),
        Claim(
            "Even `dwell=10`, with pools of {}, gets there in {}% of runs.",
            (pool("dwell=10", N5, 1), within("dwell=10", N5)),
        ),
        Claim(
            "A 4 s dwell keeps the mean pool at {} for n = 10 (goal: at most 3) but gives {}% "
            "of runs within n/2 (goal: at least 90%) and {}% strictly below (goal: about 60%); "
            "a 4.5 s dwell gives {}% and {}% but a mean pool of {}, with {} of 100 runs above "
            "3,",
            (
                pool("dwell=4", N10),
                within("dwell=4", N10),
                below("dwell=4", N10),
                within("dwell=4.5", N10),
                below("dwell=4.5", N10),
                pool("dwell=4.5", N10),
                over("dwell=4.5", N10),
            ),
        ),
        Claim(
            "For n = 8 both reach the goal of half the runs ({}% and {}%); n = 5 stays far "
            "from it ({}% and {}%).",
            (
                within("dwell=4", N8),
                within("dwell=4.5", N8),
                within("dwell=4", N5),
                within("dwell=4.5", N5),
            ),
        ),
        Claim(
            "pool sizes as in the paper (mean {} to {}, {} to {} runs in 100 above 3), but "
            "over 100 seeds {}%, {}% and {}% of runs within n/2 for n = 10, 8 and 5",
            (
                *_span(pools, 2),
                str(min(overs)),
                str(max(overs)),
                within("default", N10),
                within("default", N8),
                within("default", N5),
            ),
        ),
        Claim(
            "(and {}/10, {}/10 and {}/10 for our seeds 0-9)",
            (str(ten[N10]["within"]), str(ten[N8]["within"]), str(ten[N5]["within"])),
        ),
    ]

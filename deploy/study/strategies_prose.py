"""The numbers docs/strategies.md's text ("What it shows") reads from the study's runs,
checked against them (``prose.Claim``)."""

from __future__ import annotations

from typing import Any

from deploy.analysis import effects
from deploy.analysis.prose import Claim, down, fixed, up
from deploy.analysis.wilson import wilson
from deploy.study import strategies_runs as study
from deploy.study.declare import Records


def _number(value: float | None) -> str:
    """A median of steps as the table prints it, without a needless ``.0``."""
    if value is None:
        return "-"
    return f"{value:g}"


def claims(records: Records) -> list[Claim]:
    well = {(row["strategy"], row["n"]): row for row in study.wellstirred_rows(records)}
    swarm = study.swarm_rows(records)
    if len(well) < len(study.STRATEGIES) * len(study.WELLSTIRRED_OPTIONS) or not swarm:
        return []
    return [
        Claim("Read from the complete study above ({} runs,", (str(len(records.runs)),)),
        *_wellstirred(well),
        *_swarm(swarm),
    ]


def _wellstirred(well: dict[tuple[str, int], dict[str, Any]]) -> list[Claim]:
    options = study.WELLSTIRRED_OPTIONS
    ordered = all(
        (well["dmmd", n]["median"] or 0) < (well["dmvd", n]["median"] or 0)
        and well["dmmd", n]["correct"] < well["dmvd", n]["correct"] + (n == options[0])
        for n in options
    )
    faster_up_to = max(
        (
            n
            for n in options
            if (ratio := effects.median_ratio(well["dc", n]["times"], well["paper", n]["times"]))
            and ratio.low > 1
        ),
        default=None,
    )
    last = options[-1]
    return [
        Claim(
            ("DMMD is faster but less accurate than DMVD at every n" if ordered else "DMMD is not")
            + ": at n = 5, {} steps and {}/100 right against {} steps and {}/100; at n = 20, {} "
            "steps and {}/100 against {} steps and {}/100",
            (
                _number(well["dmmd", 5]["median"]),
                str(well["dmmd", 5]["correct"]),
                _number(well["dmvd", 5]["median"]),
                str(well["dmvd", 5]["correct"]),
                _number(well["dmmd", 20]["median"]),
                str(well["dmmd", 20]["correct"]),
                _number(well["dmvd", 20]["median"]),
                str(well["dmvd", 20]["correct"]),
            ),
        ),
        Claim(
            (
                "Negative updating and DC are right in every run at every n"
                if all(
                    well[s, n]["correct"] == well[s, n]["runs"]
                    for s in ("paper", "dc")
                    for n in options
                )
                else "Negative updating and DC are not right in every run"
            )
            + "; negative updating is faster up to n = {} and as fast at n = {}",
            (str(faster_up_to), str(last)),
        ),
        Claim(
            "The paper's agents need a median of {} steps at n = 5 and {} at n = 100 (the "
            "paper's claim of scalability in n), DC's {} and {}; DMVD and DMMD fall to {}/100 "
            "and {}/100 right at n = 100.",
            (
                _number(well["paper", 5]["median"]),
                _number(well["paper", last]["median"]),
                _number(well["dc", 5]["median"]),
                _number(well["dc", last]["median"]),
                str(well["dmvd", last]["correct"]),
                str(well["dmmd", last]["correct"]),
            ),
        ),
    ]


def _swarm(rows: list[dict[str, Any]]) -> list[Claim]:
    def mine(strategy: str, robots: int, **more: Any) -> list[dict[str, Any]]:
        return [
            row
            for row in rows
            if row["strategy"] == strategy
            and row["robots"] == robots
            and all(row[key] == value for key, value in more.items())
        ]

    def total(found: list[dict[str, Any]], key: str) -> int:
        return sum(int(row[key]) for row in found)

    sizes = sorted(study.SEEDS)
    paper = {robots: mine("paper", robots) for robots in sizes}
    ratios: dict[int, list[effects.Estimate]] = {robots: [] for robots in sizes}
    for row in rows:
        if row["strategy"] == "paper":
            continue
        baseline = next(
            other
            for other in paper[row["robots"]]
            if (other["n"], other["drop"]) == (row["n"], row["drop"])
        )
        if (found := effects.paired_median_ratio(row["by_seed"], baseline["by_seed"])) is not None:
            ratios[row["robots"]].append(found)
    small, large = sizes
    medians = {robots: [row["median"] for row in paper[robots]] for robots in sizes}
    dc_small = mine("dc", small)
    up_to_ten = [row for row in dc_small if row["n"] <= 10]
    split_up_to_ten = [row for row in up_to_ten if row["split"]]
    twenty = [row for row in dc_small if row["n"] == 20]
    dc_large = mine("dc", large)
    voters = ("dmvd", "dmmd")
    at_twenty = [row for strategy in voters for row in mine(strategy, small, n=20)]
    lossless = {
        (strategy, robots): (
            total(mine(strategy, robots, drop=0.0), "correct"),
            total(mine(strategy, robots, drop=0.0), "runs"),
        )
        for strategy in ("dmvd", "dmmd", "dc")
        for robots in sizes
    }
    lossy = {
        (strategy, robots): (
            total(mine(strategy, robots, drop=0.2), "correct"),
            total(mine(strategy, robots, drop=0.2), "runs"),
        )
        for strategy in ("dmvd", "dmmd", "dc")
        for robots in sizes
    }
    overlap = all(_overlap(lossless[key], lossy[key]) for key in lossless)
    return [
        Claim(
            "In the swarm, the paper's strategy was right in all {} runs**: {} with 10 robots "
            "and {} with 50"
            if all(total(found, "correct") == total(found, "runs") for found in paper.values())
            else "In the swarm, the paper's strategy was not right in all {} runs**: {} with "
            "10 robots and {} with 50",
            (
                str(sum(total(found, "runs") for found in paper.values())),
                str(total(paper[small], "runs")),
                str(total(paper[large], "runs")),
            ),
        ),
        Claim(
            "Its median time to consensus was {} to {} sim s with 10 robots and {} to {} with 50",
            (
                fixed(min(medians[small])),
                fixed(max(medians[small])),
                fixed(min(medians[large])),
                fixed(max(medians[large])),
            ),
        ),
        Claim(
            "At every point where a rival had enough right runs to compare times ({} or more), "
            "its median time was {} to {} times the paper's with 10 robots and {} to {} times "
            "with 50 (ratios of medians; the lowest 95% interval starts at {})",
            (
                str(effects.MIN_RUNS),
                down(min(r.value for r in ratios[small]), 1),
                up(max(r.value for r in ratios[small]), 1),
                down(min(r.value for r in ratios[large]), 1),
                up(max(r.value for r in ratios[large]), 1),
                down(min(r.low for found in ratios.values() for r in found), 2),
            ),
        ),
        Claim(
            "With 10 robots it was right in {} of {} runs up to n = 10 ("
            + _word(total(up_to_ten, "split"))
            + " split, at n = 10 with loss), but in {} of {} at n = 20, where {} runs ended in "
            "consensus on another site.",
            (
                str(total(up_to_ten, "correct")),
                str(total(up_to_ten, "runs")),
                str(total(twenty, "correct")),
                str(total(twenty, "runs")),
                str(total(twenty, "wrong")),
            ),
        )
        if len(split_up_to_ten) == 1
        and (split_up_to_ten[0]["n"], split_up_to_ten[0]["drop"]) == (10, 0.2)
        else Claim(
            "With 10 robots it was right in {} of {} runs up to n = 10",
            (str(total(up_to_ten, "correct")), str(total(up_to_ten, "runs"))),
        ),
        Claim(
            "DC was right in {} of {} runs; the other {} ended split.",
            (
                str(total(dc_large, "correct")),
                str(total(dc_large, "runs")),
                str(total(dc_large, "split")),
            ),
        ),
        Claim(
            "With 10 robots they were right in {} and {} of {} runs, mostly ending in consensus "
            "on another site ({} and {} runs), and in {} of {} runs at n = 20. With 50 robots "
            "they were right in {} and {} of {} runs; most runs ended split ({} and {})",
            (
                *(str(total(mine(s, small), "correct")) for s in voters),
                str(total(mine("dmvd", small), "runs")),
                *(str(total(mine(s, small), "wrong")) for s in voters),
                str(total(at_twenty, "correct")),
                str(total(at_twenty, "runs")),
                *(str(total(mine(s, large), "correct")) for s in voters),
                str(total(mine("dmvd", large), "runs")),
                *(str(total(mine(s, large), "split")) for s in voters),
            ),
        ),
        Claim(
            (
                "the rivals' right runs with and without loss are within each other's 95% "
                "intervals at both sizes"
                if overlap
                else "the rivals' right runs with and without loss are not all within each "
                "other's 95% intervals"
            )
            + " (for example DC with 50 robots: {}/{} without and {}/{} with loss)",
            (
                str(lossless["dc", large][0]),
                str(lossless["dc", large][1]),
                str(lossy["dc", large][0]),
                str(lossy["dc", large][1]),
            ),
        ),
    ]


def _word(count: int) -> str:
    return {1: "one", 2: "two", 3: "three"}.get(count, str(count))


def _overlap(first: tuple[int, int], second: tuple[int, int]) -> bool:
    low_one, high_one = wilson(*first)
    low_two, high_two = wilson(*second)
    return low_one <= high_two and low_two <= high_one

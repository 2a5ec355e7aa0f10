"""What docs/robustness.md's text says of the runs: its findings, rendered from the results
file as the tables are (the short answers, the comparison counts, the price of distrust),
and the numbers of its hand-written prose, checked against the runs (``prose.Claim``)."""

from __future__ import annotations

import statistics
from typing import Any

from deploy.analysis import effects
from deploy.analysis.prose import Claim, fixed
from deploy.analysis.wilson import share, wilson
from deploy.study import robustness_runs as study
from deploy.study import tables
from deploy.study.declare import Records
from deploy.study.grid import text

ALPHA0, ALPHA01, LOGLINEAR = (setup.key for setup in study.SETUPS)


def _noise(records: Records, sigma: float, controller: str, lighting: float = 0.0) -> list[Any]:
    return records.where(sweep="noise", sigma=sigma, lighting=lighting, controller=controller)


def _failing(records: Records, controller: str) -> list[dict[str, Any]]:
    """The runs of the failing noise levels (every seed they have) of one controller."""
    return [run for sigma in study.FAILING for run in _noise(records, sigma, controller)]


def _right(runs: list[dict[str, Any]]) -> int:
    return sum(bool(tables.result(run)["correct"]) for run in runs)


def _overlap(first: tuple[int, int], second: tuple[int, int]) -> bool:
    low_one, high_one = wilson(*first)
    low_two, high_two = wilson(*second)
    return low_one <= high_two and low_two <= high_one


def _keyed_times(runs: list[dict[str, Any]]) -> dict[int, float]:
    """Consensus times keyed by (sigma, seed), to pair runs across controllers."""
    return {
        int(run["params"]["sigma"]) * 1000 + int(run["seed"]): tables.result(run)["sim_time_s"]
        for run in runs
        if tables.result(run)["consensus"]
    }


def _times(estimate: effects.Estimate | None, more: str = "") -> str:
    if estimate is None:
        return f"(too few runs to compare times{more})"
    return effects.times_text(estimate, more=more)


def _and(items: list[str]) -> str:
    """``0.2``, ``0.2 and 0.7``, ``0.2, 0.5 and 0.7``."""
    return items[0] if len(items) == 1 else ", ".join(items[:-1]) + " and " + items[-1]


def _interval(estimate: effects.Estimate | None) -> str:
    return "-" if estimate is None else effects.outwards(estimate.low, estimate.high, 2)


# --- the short answers ---------------------------------------------------------------------


def answers(records: Records) -> str:
    """The page's short answers, one bullet each, from the runs."""
    drops = {level: records.where(sweep="drop", drop=level) for level in study.DROPS}
    if not all(drops.values()) or not _failing(records, ALPHA0):
        return "The short answers come when the study's runs are made."
    return "\n".join(
        [_loss(records, drops), _noise_breaks(records), _distrust(records), _dilution(records)]
    )


def _loss(records: Records, drops: dict[float, list[dict[str, Any]]]) -> str:
    every_right = all(_right(runs) == len(runs) for runs in drops.values())
    seeds = len(drops[0.0])
    clean = study.summarise(drops[0.0])["by_seed"]
    ratios = {
        level: effects.paired_median_ratio(study.summarise(runs)["by_seed"], clean)
        for level, runs in drops.items()
        if level > 0
    }
    claim = study.claim_numbers(records)
    assert claim is not None
    middle = [ratio for level, ratio in ratios.items() if level < max(study.DROPS) and ratio]
    clear = [
        text(level)
        for level, ratio in ratios.items()
        if level < max(study.DROPS) and ratio and ratio.low > 1
    ]
    worst = ratios[max(study.DROPS)]
    assert worst is not None and claim["ratio"] is not None
    accuracy = (
        f"every run of {seeds} seeds reached the right consensus at every drop rate from 0 to "
        f"{text(max(study.DROPS))}"
        if every_right
        else "not every run reached the right consensus (the table)"
    )
    lead = "costs some time and no accuracy" if every_right else "costs time and accuracy"
    said_claim = (
        "which 10 seeds cannot tell from no change"
        if claim["ratio"].low <= 1 <= claim["ratio"].high
        else "more than no change"
    )
    return (
        f"* **Radio loss {lead}.** With α = 0 and MProdOp {accuracy}. At 30 % loss the "
        f"median consensus time was {claim['median_lossy']:.0f} s against "
        f"{claim['median_clean']:.0f} s without loss: "
        + effects.times_text(
            claim["ratio"],
            more=f"; per seed {claim['per_seed'][0]:.2f} to {claim['per_seed'][1]:.2f}",
        )
        + f", {said_claim}. From 10 to 70 % loss the median is "
        f"{min(r.value for r in middle):.2f} to {max(r.value for r in middle):.2f} times that "
        "without loss"
        + (
            f" (the intervals at {_and(clear)} loss exclude 1)"
            if clear
            else " (every interval includes 1)"
        )
        + f", and at 80 % it is {effects.times_text(worst)}."
    )


def _noise_breaks(records: Records) -> str:
    first = next(
        (
            sigma
            for sigma in study.SIGMAS
            if _right(
                runs := [r for r in _noise(records, sigma, ALPHA0) if r["seed"] in study.SEEDS]
            )
            < len(runs)
        ),
        None,
    )
    swapped = next(
        (
            sigma
            for sigma in study.SENSING_SIGMAS
            for run in records.where(sweep="sensing", sigma=sigma)
            if tables.result(run)["swapped"] > 0
        ),
        None,
    )
    failing = _failing(records, ALPHA0)
    at_first = (
        [r for r in _noise(records, first, ALPHA0) if r["seed"] in study.SEEDS] if first else []
    )
    return (
        f"* **Camera noise breaks α = 0.** From pixel noise σ = {text(swapped or 0)} (on the "
        "0..255 scale) a comparison of the two best sites can come out wrong (the sensing "
        "table); with α = 0 one such comparison eliminates the best site for good and "
        f"MProdOp spreads the zero. α = 0 starts failing at σ = {text(first or 0)} "
        f"({share(_right(at_first), len(at_first))} runs right); over σ = "
        f"{text(study.FAILING[0])}..{text(study.FAILING[-1])} and {len(study.MORE_SEEDS)} seeds "
        f"per level it was right in {share(_right(failing), len(failing))}."
    )


def _distrust(records: Records) -> str:
    failing = _failing(records, ALPHA01)
    clean = study.summarise(_noise(records, 0.0, ALPHA0))["by_seed"]
    slow = study.summarise(_noise(records, 0.0, ALPHA01))["by_seed"]
    ratio = effects.paired_median_ratio(slow, clean)
    high = max(study.FAILING)
    noisy = effects.paired_median_ratio(
        study.summarise(_noise(records, high, ALPHA01))["by_seed"],
        study.summarise(_noise(records, high, ALPHA0))["by_seed"],
    )
    return (
        f"* **Distrust fixes most of it.** α = 0.1 with a 0.99 threshold was right in "
        f"{share(_right(failing), len(failing))}. It costs time: without noise its median "
        f"consensus time is {_times(ratio)} α = 0's "
        f"({statistics.median(slow.values()):.0f} s against "
        f"{statistics.median(clean.values()):.0f} s), less at high noise, where α = 0 is "
        f"slow too (at σ = {text(high)}, {_times(noisy)})."
    )


def _dilution(records: Records) -> str:
    mprodop = _failing(records, ALPHA01)
    loglinear = _failing(records, LOGLINEAR)
    counts = (_right(loglinear), len(loglinear)), (_right(mprodop), len(mprodop))
    verdict = (
        f"the 95 % intervals of the two overlap, so {len(loglinear)} runs cannot tell it from "
        "α = 0.1 with MProdOp"
        if _overlap(*counts)
        else "the 95 % intervals of the two do not overlap"
    )
    return (
        "* **The diluting operator adds little to that.** The log-linear pool we chose "
        f"(below) was right in {share(*counts[0])} with α = 0.1: {verdict}. With α = 0 it "
        "is MProdOp exactly."
    )


# --- what the comparison counts show ------------------------------------------------------


def counts(records: Records) -> str:
    """What the judged comparisons of the failing levels' runs show."""
    runs = {setup.key: _failing(records, setup.key) for setup in study.SETUPS}
    if not all(runs.values()):
        return "The comparison counts come when the failing levels' runs are made."

    def results(key: str) -> list[dict[str, Any]]:
        return [tables.result(run) for run in runs[key]]

    def misled(key: str) -> list[dict[str, Any]]:
        return [result for result in results(key) if result["best_eliminated"] > 0]

    def failed(key: str) -> list[dict[str, Any]]:
        return [result for result in results(key) if not result["correct"]]

    def verdicts(found: list[dict[str, Any]], verdict: str) -> int:
        return sum(result["verdict"] == verdict for result in found)

    zero_misled, zero_clean = (
        misled(ALPHA0),
        [result for result in results(ALPHA0) if result["best_eliminated"] == 0],
    )
    zero_failed = failed(ALPHA0)
    high = [sigma for sigma in study.FAILING if sigma >= 170]
    missed = [
        100 * result["missed"] / (2 * result["frames"])
        for sigma in high
        for run in records.where(sweep="sensing", sigma=sigma)
        if (result := tables.result(run))
    ]
    per_run = [
        statistics.fmean(tables.result(run)["comparisons"] for run in _noise(records, sigma, key))
        for sigma in high
        for key in (ALPHA01, LOGLINEAR)
    ]

    def late(key: str) -> int:
        return sum(
            not tables.result(run)["correct"] and run["params"]["sigma"] >= 170 for run in runs[key]
        )

    def rest(key: str) -> str:
        found = failed(key)
        parts = [
            f"{verdicts(found, verdict)} {name}"
            for verdict, name in (("split", "splits"), ("undecided", "undecided at 1800 s"))
            if verdicts(found, verdict)
        ]
        return ", ".join(parts) or "none other"

    total = sum(len(found) for found in runs.values())
    return (
        f"What the comparison counts show. In these {total} runs, "
        + (
            "every α = 0 run in which some robot eliminated the best site by a wrong "
            f"comparison failed ({sum(r['correct'] for r in zero_misled)} of "
            f"{len(zero_misled)} recovered)"
            if not any(r["correct"] for r in zero_misled)
            else f"α = 0 runs in which some robot eliminated the best site by a wrong "
            f"comparison recovered in {sum(r['correct'] for r in zero_misled)} of "
            f"{len(zero_misled)}"
        )
        + ": with α = 0 the best site's probability becomes exactly 0, MProdOp carries the 0 "
        "to every robot that pools with that one, and no later evidence can bring it back. "
        f"The α = 0 runs without such a comparison were right in "
        f"{sum(r['correct'] for r in zero_clean)} of {len(zero_clean)}. Of the α = 0 failures "
        f"{verdicts(zero_failed, 'split')} of {len(zero_failed)} are splits (robots that "
        "pooled with the misled one chose another site, the rest the best) and "
        f"{verdicts(zero_failed, 'wrong')} a wrong consensus. With α = 0.1 the wrong "
        "elimination only multiplies the best site's probability by 1/9, and the swarm "
        f"recovered in {sum(r['correct'] for r in misled(ALPHA01))} of "
        f"{len(misled(ALPHA01))} such runs with MProdOp and "
        f"{sum(r['correct'] for r in misled(LOGLINEAR))} of {len(misled(LOGLINEAR))} with the "
        f"log-linear pool. Of the failures with α > 0, {late(ALPHA01)} of "
        f"{len(failed(ALPHA01))} with MProdOp and {late(LOGLINEAR)} of {len(failed(LOGLINEAR))} "
        f"with the log-linear pool are at σ ≥ 170, where {min(missed):.0f} to "
        f"{max(missed):.0f} % of frames are missed (the sensing table), so few comparisons "
        f"are made ({min(per_run):.0f} to {max(per_run):.0f} per run). A wrong consensus: "
        f"{verdicts(failed(ALPHA01), 'wrong')} of {len(failed(ALPHA01))} with MProdOp "
        f"({rest(ALPHA01)}), {verdicts(failed(LOGLINEAR), 'wrong')} of "
        f"{len(failed(LOGLINEAR))} with the log-linear pool ({rest(LOGLINEAR)})."
    )


def price(records: Records) -> str:
    """What distrust costs without noise."""
    clean, slow = _noise(records, 0.0, ALPHA0), _noise(records, 0.0, ALPHA01)
    if not clean or not slow:
        return "The price of distrust comes when the runs without noise are made."
    before, after = study.summarise(clean), study.summarise(slow)
    ratio = effects.paired_median_ratio(after["by_seed"], before["by_seed"])
    more = 100 * (after["comparisons"] / before["comparisons"] - 1)
    after_median, before_median = after["time_median"], before["time_median"]
    return (
        "The price of distrust: without noise, the median consensus time of α = 0.1 is "
        f"{_times(ratio, more=f'; {after_median:.0f} s against {before_median:.0f} s')} "
        f"that of α = 0, and it takes {more:.0f} % more comparisons "
        f"({after['comparisons']:.1f} against {before['comparisons']:.1f} per run): with "
        "odds of 9 per elimination, the 0.99 threshold needs the evidence against every "
        "other site about three times over (9 × 9^−3 ≈ 1 %), where α = 0 needs it once."
    )


def blocks(records: Records) -> dict[str, str]:
    return {"answers": answers(records), "counts": counts(records), "price": price(records)}


# --- the hand-written prose's numbers ---------------------------------------------------------


def claims(records: Records) -> list[Claim]:
    found = [
        Claim(
            "confirms for {} runs with real processes",
            (str(len(records.where(sweep="processes"))),),
        )
    ]
    clean = records.where(sweep="drop", drop=0.0)
    lossy = records.where(sweep="drop", drop=max(study.DROPS))
    if clean and lossy:
        before, after = study.summarise(clean), study.summarise(lossy)
        ratio = effects.paired_median_ratio(after["by_seed"], before["by_seed"])
        assert ratio is not None
        found.append(
            Claim(
                "the swarm needed more comparisons ({} per run against {}) and its median "
                "consensus time was {} times that without loss",
                (fixed(after["comparisons"]), fixed(before["comparisons"]), fixed(ratio.value, 2)),
            )
        )
    identical, total, wrong = 0, 0, 0
    for setup in study.SETUPS:
        base = {run["seed"]: tables.result(run) for run in _noise(records, 0.0, setup.key)}
        for run in _noise(records, 100.0, setup.key):
            total += 1
            wrong += tables.result(run)["wrong_comparisons"]
            twin = base.get(run["seed"])
            identical += twin is not None and twin["digest"] == tables.result(run)["digest"]
    if total:
        found.append(
            Claim(
                "(at σ = 100, {} of {} runs were run for run identical to σ = 0 and "
                + (
                    "no comparison was wrong)" if wrong == 0 else f"{wrong} comparisons were wrong)"
                ),
                (str(identical), str(total)),
            )
        )
    sensing = {run["params"]["sigma"]: tables.result(run) for run in records.where(sweep="sensing")}
    swapped = [sigma for sigma, result in sorted(sensing.items()) if result["swapped"]]
    missed = [sigma for sigma, result in sorted(sensing.items()) if result["missed"]]
    if swapped and missed:
        found.append(
            Claim(
                "swap the best two sites (from σ = {} in the table below), and then frames are "
                "missed (from σ = {}:",
                (text(swapped[0]), text(missed[0])),
            )
        )
    found += _lighting(records)
    mprodop, loglinear = _failing(records, ALPHA01), _failing(records, LOGLINEAR)
    if mprodop and loglinear:
        more = []
        for sigma in study.FAILING:
            ours = [tables.result(r)["comparisons"] for r in _noise(records, sigma, LOGLINEAR)]
            theirs = [tables.result(r)["comparisons"] for r in _noise(records, sigma, ALPHA01)]
            more.append(100 * (statistics.fmean(ours) / statistics.fmean(theirs) - 1))
        ratio = effects.paired_median_ratio(_keyed_times(loglinear), _keyed_times(mprodop))
        assert ratio is not None
        found.append(
            Claim(
                "MProdOp ({} against {} right of {} at σ = 150..180: "
                + (
                    "overlapping"
                    if _overlap(
                        (_right(loglinear), len(loglinear)), (_right(mprodop), len(mprodop))
                    )
                    else "separate"
                )
                + " 95 % intervals, no difference that {} runs can resolve), takes {} to {} % "
                "more comparisons there, and its median consensus time there is {} times "
                "MProdOp's ({}-{})",
                (
                    str(_right(loglinear)),
                    str(_right(mprodop)),
                    str(len(loglinear)),
                    str(len(loglinear)),
                    fixed(min(more)),
                    fixed(max(more)),
                    fixed(ratio.value, 2),
                    *_interval(ratio).split("-"),
                ),
            )
        )
    return found


def _lighting(records: Records) -> list[Claim]:
    plain = {setup.key: _noise(records, 0.0, setup.key, study.LIGHTING) for setup in study.SETUPS}
    noisy = {setup.key: _noise(records, 100.0, setup.key, study.LIGHTING) for setup in study.SETUPS}
    if not all(plain.values()) or not all(noisy.values()):
        return []
    zero = [tables.result(run) for run in plain[ALPHA0]]
    wrong = 100 * sum(r["wrong_comparisons"] for r in zero) / sum(r["comparisons"] for r in zero)
    eliminated = sum(
        tables.result(run)["best_eliminated"] for runs in plain.values() for run in runs
    )
    all_right = all(_right(runs) == len(runs) for runs in plain.values())
    failed = {
        key: {
            run["seed"]: tables.result(run)["verdict"]
            for run in runs
            if not tables.result(run)["correct"]
        }
        for key, runs in noisy.items()
    }
    every = sorted(set(failed[ALPHA0]) & set(failed[ALPHA01]) & set(failed[LOGLINEAR]))
    two = sorted((set(failed[ALPHA0]) & set(failed[ALPHA01])) - set(every))
    alone = sorted(set(failed[ALPHA0]) - set(failed[ALPHA01]) - set(failed[LOGLINEAR]))
    unfinished = all(failed[key][seed] == "undecided" for key in failed for seed in every)
    split = all(failed[ALPHA0][seed] == "split" for seed in alone)
    return [
        Claim(
            "no pixel noise, {} % of the α = 0 comparisons were wrong (worse sites swapped), "
            + (
                "but none eliminated the best"
                if eliminated == 0
                else f"{eliminated} eliminated the best"
            )
            + (
                " and all {} runs of every controller were right"
                if all_right
                else ", and of {} runs a controller some were wrong"
            ),
            (fixed(wrong, 1), str(len(plain[ALPHA0]))),
        ),
        Claim(
            "α = 0 was right in {} of {} runs, α = 0.1 with MProdOp in {} and with the "
            "log-linear pool in {}",
            (
                str(_right(noisy[ALPHA0])),
                str(len(noisy[ALPHA0])),
                str(_right(noisy[ALPHA01])),
                str(_right(noisy[LOGLINEAR])),
            ),
        ),
        Claim(
            f"{_seeds(every)} "
            + ("did not finish by 1800 s" if unfinished else "failed")
            + f" with any of the three controllers, {_seeds(two)} neither with α = 0 nor with "
            f"α = 0.1 and MProdOp, and with α = 0 {_seeds(alone)} "
            + ("split" if split else "failed"),
            tuple(str(seed) for seed in every + two + alone),
        ),
    ]


def _seeds(seeds: list[int]) -> str:
    """``seed {}``, ``seeds {} and {}``, ``seeds {}, {} and {}``; ``no seed``."""
    if not seeds:
        return "no seed"
    if len(seeds) == 1:
        return "seed {}"
    return "seeds " + ", ".join(["{}"] * (len(seeds) - 1)) + " and {}"

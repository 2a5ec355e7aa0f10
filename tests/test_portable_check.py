"""``make check-portable`` (portable/): the parts that decide what it runs and what it
calls a match, without an emulator. The check itself runs the published runs under qemu
(docs/testing.md, "make check-portable")."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import pytest

from portable import c_robot, check, machines, probe, published

REPO = Path(__file__).resolve().parent.parent


def test_the_fixed_runs_are_runs_of_every_kind_the_check_promises() -> None:
    from deploy.study import catalogue

    jobs = published.every_job()
    fixed = [jobs[key] for key in published.FIXED]
    sources = {job.source for job in fixed}
    assert {"section5", "scale", "strategies", "wellstirred", "run", "kernel"} <= sources
    variants = {job.args["variant"] for job in fixed if job.source == "section5"}
    assert variants == {"default", "linger"}
    assert all(job.published is not None for job in fixed if job.source == "section5")
    # Each fixed study run is a run its study declares: 50 robots, and a rival with loss.
    declared = {
        job.source: {run.key: run for run in catalogue.study_named(job.source).runs()}
        for job in fixed
        if job.source in published.SOURCES[1:]
    }
    scale = next(job for job in fixed if job.source == "scale")
    assert int(dict(declared["scale"][scale.args["key"]].params)["robots"]) >= 50
    rival = dict(
        declared["strategies"][
            next(j for j in fixed if j.source == "strategies").args["key"]
        ].params
    )
    assert rival["strategy"] != "paper" and float(rival["drop"]) > 0
    noisy = next(job for job in fixed if job.source == "run")
    assert "--camera-noise" in noisy.args["options"] and "--drop" in noisy.args["options"]


def test_a_sample_is_the_same_for_a_seed_and_another_for_another_seed() -> None:
    first = [job.key for job in published.choose(8, 3)]
    assert first == [job.key for job in published.choose(8, 3)]
    other = [job.key for job in published.choose(8, 4)]
    assert first[: len(published.FIXED)] == list(published.FIXED)
    assert first[len(published.FIXED) :] != other[len(published.FIXED) :]
    assert len(set(first)) == len(first)
    alone = [job.key for job in published.choose(8, 3, fixed=False)]
    assert alone == first[len(published.FIXED) :]


def test_a_sample_takes_each_published_file_in_turn_and_only_affordable_runs() -> None:
    jobs = published.every_job()
    drawn = published.sample(jobs, 8, 0, published.FIXED)
    sources = [
        source
        for source in published.SOURCES
        if any(
            job.source == source and job.seconds <= published.MAX_SAMPLE_SECONDS
            for job in jobs.values()
        )
    ]
    assert [job.source for job in drawn][: len(sources)] == sources
    assert all(job.seconds <= published.MAX_SAMPLE_SECONDS for job in drawn)
    assert not {job.key for job in drawn} & set(published.FIXED)
    assert all(job.published is not None for job in drawn)


def test_runs_can_be_named_and_a_name_that_is_no_run_is_refused(
    capsys: pytest.CaptureFixture[str],
) -> None:
    assert [job.key for job in published.choose(5, 0, ["section5/default/n5/s3"])] == [
        "section5/default/n5/s3"
    ]
    with pytest.raises(SystemExit) as exit_info:
        check.main(["--runs", "section5/default/n5/s999"])
    assert exit_info.value.code == 2
    errors = [line for line in capsys.readouterr().err.splitlines() if "error:" in line]
    assert len(errors) == 1 and "section5/default/n5/s999" in errors[0]


@pytest.mark.parametrize("arguments", [["--sample", "-1"], ["--jobs", "0"], ["--machines", "x"]])
def test_bad_arguments_give_one_line_and_exit_code_2(
    arguments: list[str], capsys: pytest.CaptureFixture[str]
) -> None:
    with pytest.raises(SystemExit) as exit_info:
        check.main(arguments)
    assert exit_info.value.code == 2
    assert len([line for line in capsys.readouterr().err.splitlines() if "error:" in line]) == 1


def test_list_prints_the_runs_and_runs_nothing(capsys: pytest.CaptureFixture[str]) -> None:
    assert check.main(["--list", "--sample", "2", "--seed", "5"]) == 0
    keys = [line.split(" natively  ")[1] for line in capsys.readouterr().out.splitlines()]
    assert keys == [job.key for job in published.choose(2, 5)]


def test_the_figure_1_table_is_rendered_as_the_page_has_it_and_a_changed_mean_shows() -> None:
    records, _ = probe.wellstirred({})  # swarm wellstirred --exact --json, in this process
    assert published.render_figure1(records) == published.figure1_table()
    records[2] = {**records[2], "mean": records[2]["mean"] + 0.01}  # n = 10, k = 3
    changed = published.differences(published.figure1_table(), published.render_figure1(records))
    assert len(changed) == 1 and changed[0].startswith("| 10 (5) |")


def test_differences_name_each_field_that_changed() -> None:
    old = {"sim_time_s": 140.6, "steps": [4, 3], "ended": "consensus"}
    assert published.differences(old, dict(old)) == []
    assert published.differences(old, {**old, "steps": [4, 4]}) == ["steps: [4, 3] -> [4, 4]"]
    assert published.without_wall({"a": 1, "wall_s": 2.0, "wall_time_s": 3.0}) == {"a": 1}


def test_a_probe_job_gives_the_published_record_and_the_runs_digest() -> None:
    job = published.every_job()["section5/default/n5/s0"]
    record, run = probe.section5(job.args)
    assert record == job.published
    assert run is not None and len(run["digest"]) == 16
    assert [robot[2] for robot in run["per_robot"]] == record["steps"]


def test_the_probe_takes_each_summary_and_puts_the_engine_back() -> None:
    from deploy.inprocess import engine

    original = engine.run_in_process
    with probe.summaries() as seen:
        assert engine.run_in_process is not original
    assert engine.run_in_process is original and seen == []


def test_each_emulated_machine_must_report_the_cpu_it_names() -> None:
    haswell, nehalem = machines.haswell(), machines.nehalem()
    avx2 = {"machine": "x86_64", "numpy_simd": ["X86_V3"]}
    assert haswell.expect(avx2) == []
    assert haswell.expect({**avx2, "numpy_simd": ["X86_V3", "X86_V4"]}) != []
    assert nehalem.expect({"machine": "x86_64", "numpy_simd": []}) == []
    assert nehalem.expect(avx2) != []
    arm = machines.Aarch64Python(Path("/nonexistent")).machine()
    assert arm.expect({"machine": "aarch64", "numpy_simd": ["ASIMDHP"]}) == []
    assert arm.expect({"machine": "x86_64", "numpy_simd": []}) != []
    pi = machines.Aarch64Python(Path("/nonexistent")).machine("cortex-a72")
    assert pi.prefix[:3] == ("qemu-aarch64", "-cpu", "cortex-a72")
    assert pi.expect({"machine": "aarch64", "numpy_simd": []}) == []
    assert pi.expect({"machine": "aarch64", "numpy_simd": ["ASIMDHP"]}) != []


def test_no_probe_inherits_what_masks_cpu_features(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("NPY_DISABLE_CPU_FEATURES", "AVX512F")
    monkeypatch.setenv("GLIBC_TUNABLES", "glibc.cpu.hwcaps=-AVX2")
    environment = machines.haswell().env()
    assert "NPY_DISABLE_CPU_FEATURES" not in environment
    assert "GLIBC_TUNABLES" not in environment


def test_a_missing_emulator_is_one_line_saying_what_to_install(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setattr(machines.shutil, "which", lambda name: None)
    monkeypatch.setattr(machines.os, "geteuid", lambda: 1000)
    with pytest.raises(machines.SetupError) as error:
        machines.ensure_tools(["qemu-x86_64", "aarch64-linux-gnu-gcc"], print)
    message = str(error.value)
    assert "\n" not in message and "qemu-x86_64" in message
    assert "apt-get install --no-install-recommends" in message
    assert "qemu-user" in message and "gcc-aarch64-linux-gnu" in message


def test_the_run_lock_splits_into_entries_with_their_hashes() -> None:
    text = machines.RUN_LOCK.read_text()
    blocks = machines.lock_blocks(text)
    names = [name for name, _ in blocks]  # a name twice: two versions, for two markers
    assert len(set(names)) > 10 and set(machines.SOURCE_ONLY) <= set(names)
    assert all(entry.lower().replace("_", "-").startswith(name) for name, entry in blocks)
    assert all("==" in entry and "--hash=sha256:" in entry for _, entry in blocks)
    assert sum(entry.count("--hash=") for _, entry in blocks) == text.count("--hash=")


def test_the_cross_builds_compile_flags_are_checked() -> None:
    good = "aarch64-linux-gnu-gcc -std=c99 -O2 -ffp-contract=off -c src/rng.c -o build/x/rng.o"
    assert c_robot.compile_problems(good, c_robot.CROSS) == []
    fused = good.replace(" -ffp-contract=off", "")
    assert len(c_robot.compile_problems(fused, c_robot.CROSS)) == 1
    tuned = good.replace("-O2", "-O2 -march=armv8.2-a")
    assert len(c_robot.compile_problems(tuned, c_robot.CROSS)) == 1
    assert c_robot.compile_problems("", c_robot.CROSS) != []


def test_chunks_share_out_every_job_once_longest_first() -> None:
    jobs = [
        dataclasses.replace(published.every_job()["kernel"], key=str(i), seconds=float(i))
        for i in range(1, 8)
    ]
    groups = check.chunks(jobs, 2)
    assert sorted(job.key for group in groups for job in group) == sorted(job.key for job in jobs)
    totals = sorted(sum(job.seconds for job in group) for group in groups)
    assert totals == [14.0, 14.0]
    assert check.chunks(jobs[:1], 3) == [jobs[:1]]


def test_a_records_name_is_its_content() -> None:
    record = json.loads('{"b": [1, 2], "a": 0.1}')
    assert check.record_hash(record) == check.record_hash({"a": 0.1, "b": [1, 2]})
    assert check.record_hash(record) != check.record_hash({"a": 0.1, "b": [1, 3]})


def test_only_the_probes_json_objects_are_its_lines() -> None:
    assert check.probe_line('{"key": "kernel", "seconds": 0.1}\n') == {
        "key": "kernel",
        "seconds": 0.1,
    }
    assert check.probe_line("OpenCV: a warning\n") is None
    assert check.probe_line("1\n") is None

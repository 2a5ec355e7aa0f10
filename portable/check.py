"""``make check-portable`` (``python -m portable``): published runs again on emulated CPUs,
and the C robot on aarch64.

Each chosen job (portable/published.py: fixed ones and a seeded sample of the other
published runs) runs natively and on every emulated machine (portable/machines.py:
x86-64 without AVX-512, x86-64-v2 without AVX, aarch64), each machine's jobs in one or
a few probe processes (portable/probe.py). Every result must equal the native one (the
run digest, every robot's decided site, steps, decision time and pool sizes, the sim
time, the radio counts; the whole record of what no run digest covers), and the native
and emulated records must equal the published ones. Each emulated interpreter must also
report the CPU it is said to be (numpy's SIMD features, the machine name), or the check
would show nothing. The C robot (portable/c_robot.py) is cross-built for aarch64, its
unit tests run under qemu-aarch64, and a lockstep run with it must be the all-emulated
run of its seed.

    python -m portable                       # the fixed runs and a sample of 3 (seed 0)
    python -m portable --sample 6 --seed 7   # another sample of published runs
    python -m portable --sample 6 --seed 7 --sample-only --machines haswell aarch64
    python -m portable --list                # which runs, without running them
    python -m portable --machines haswell --no-c-robot --runs section5/default/n5/s3

It prints a line per result as it comes, then one summary line; exit code 0 only when
every comparison matched, 1 when any differs, 2 for bad arguments or a tool or package
that is missing and cannot be installed (the one-line message says what to install).
"""

from __future__ import annotations

import argparse
import concurrent.futures
import hashlib
import json
import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from portable import c_robot, machines, published
from portable.machines import Machine, SetupError
from portable.published import Job

REPO = published.REPO
MACHINES = ("haswell", "nehalem", "aarch64")
AARCH64 = ("aarch64", "cortex-a72")  # cortex-a72: only when asked for
DEFAULT_SAMPLE = 3
PROBE_TIMEOUT = 5400.0  # wall seconds for one probe process


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="check-portable",
        description="Published runs again on emulated CPUs (qemu-user), compared with this "
        "machine's runs and the published files; the C robot on aarch64.",
    )
    parser.add_argument(
        "--sample",
        type=int,
        default=DEFAULT_SAMPLE,
        metavar="N",
        help=f"other published runs to add to the fixed ones (default: {DEFAULT_SAMPLE})",
    )
    parser.add_argument("--seed", type=int, default=0, help="the sample's seed (default: 0)")
    parser.add_argument(
        "--sample-only", action="store_true", help="the sample without the fixed runs"
    )
    parser.add_argument(
        "--runs",
        nargs="+",
        metavar="KEY",
        default=[],
        help="exactly these runs (keys as --list prints them), no others",
    )
    parser.add_argument(
        "--machines",
        nargs="+",
        choices=[*MACHINES, "cortex-a72"],
        default=list(MACHINES),
        help="the emulated machines (default: haswell nehalem aarch64; cortex-a72 on request)",
    )
    parser.add_argument("--no-c-robot", action="store_true", help="leave the C robot out")
    parser.add_argument(
        "--c-robot-seed",
        type=int,
        default=0,
        metavar="S",
        help="the seed of the lockstep run with the aarch64 C robot",
    )
    parser.add_argument(
        "--jobs", type=int, default=2, metavar="J", help="processes at once (default: 2)"
    )
    parser.add_argument(
        "--cache",
        type=Path,
        default=REPO / ".portable",
        help="where downloads and the aarch64 interpreter are kept (default: .portable/)",
    )
    parser.add_argument("--list", action="store_true", help="print the runs and exit")
    return parser


def record_hash(record: Any) -> str:
    """16 hex digits naming a record (for the progress lines of what has no run digest)."""
    text = json.dumps(record, sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def chunks(jobs: Sequence[Job], count: int) -> list[list[Job]]:
    """``jobs`` in at most ``count`` groups of about equal native time, longest first in
    each (every job in exactly one group; no empty group)."""
    groups: list[tuple[float, list[Job]]] = [(0.0, []) for _ in range(max(1, count))]
    for job in sorted(jobs, key=lambda job: -job.seconds):
        index = min(range(len(groups)), key=lambda i: groups[i][0])
        total, members = groups[index]
        groups[index] = (total + job.seconds, [*members, job])
    return [members for _, members in groups if members]


def probe_line(text: str) -> dict[str, Any] | None:
    """A line of the probe's (a JSON object), or None for anything else."""
    try:
        line = json.loads(text)
    except ValueError:
        return None
    return line if isinstance(line, dict) else None


@dataclass
class Tally:
    """Every comparison made, and the differences found; thread-safe, it also prints."""

    started: float = field(default_factory=time.monotonic)
    compared: int = 0
    failures: list[str] = field(default_factory=list)
    lock: threading.Lock = field(default_factory=threading.Lock)

    def say(self, text: str) -> None:
        with self.lock:
            print(f"[{time.monotonic() - self.started:5.0f} s] {text}", flush=True)

    def add(self, ok: bool, failure: str) -> bool:
        with self.lock:
            self.compared += 1
            if not ok:
                self.failures.append(failure)
        return ok


@dataclass
class Check:
    """One check: its jobs, machines and the native results every machine is held to."""

    jobs: list[Job]
    machines: list[Machine]
    cache: Path
    tally: Tally
    workers: int
    native: dict[str, dict[str, Any]] = field(default_factory=dict)
    native_done: threading.Event = field(default_factory=threading.Event)
    processes: list[subprocess.Popen[str]] = field(default_factory=list)
    stopping: bool = False

    @property
    def by_key(self) -> dict[str, Job]:
        return {job.key: job for job in self.jobs}

    # --- one probe process --------------------------------------------------------------

    def probe(self, machine: Machine, jobs: list[Job], part: int) -> None:
        """Run ``jobs`` in one interpreter on ``machine``, judging each result as it comes."""
        self.cache.mkdir(parents=True, exist_ok=True)
        stem = f"{machine.name}-{part}"
        jobs_file = self.cache / f"jobs-{stem}.json"
        jobs_file.write_text(json.dumps([job.spec() for job in jobs]))
        errors_file = self.cache / f"probe-{stem}.err"
        seen: set[str] = set()
        done = False
        with errors_file.open("w") as errors:
            process = subprocess.Popen(
                machine.command("-m", "portable.probe", str(jobs_file)),
                cwd=REPO,
                env=machine.env(),
                stdout=subprocess.PIPE,
                stderr=errors,
                text=True,
            )
            self.processes.append(process)
            timer = threading.Timer(PROBE_TIMEOUT, process.kill)
            timer.start()
            try:
                assert process.stdout is not None
                for text in process.stdout:
                    line = probe_line(text)
                    if line is None:  # not the probe's: a library's own output
                        errors.write(f"(on standard output) {text}")
                        continue
                    if "about" in line:
                        self.judge_machine(machine, line["about"], part)
                    elif "done" in line:
                        done = True
                        self.say_compiled(machine, line["done"], part)
                    else:
                        seen.add(line["key"])
                        self.judge(machine, line)
                process.wait()
            finally:
                timer.cancel()
        if (not done or process.returncode != 0) and not self.stopping:
            tail = [
                line
                for line in errors_file.read_text().splitlines()
                if line.strip() and machines.QEMU_NOISE not in line
            ][-3:]
            missing = [job.key for job in jobs if job.key not in seen]
            self.tally.add(
                False,
                f"{machine.name}: the probe ended with exit code {process.returncode} before "
                f"{len(missing)} run(s) ({', '.join(missing[:3])}): {' / '.join(tail)}",
            )
            self.tally.say(f"{machine.name:10} probe FAILED (exit {process.returncode})")

    def judge_machine(self, machine: Machine, about: dict[str, Any], part: int) -> None:
        """Each emulated interpreter must be on the CPU its machine names (it prints once
        per machine)."""
        problems = machine.expect(about)
        if machine.name != "native":
            self.tally.add(
                not problems, f"{machine.name}: not the CPU it should be: " + "; ".join(problems)
            )
        if part == 0 or problems:
            simd = ",".join(about.get("numpy_simd", [])) or "nothing beyond its baseline"
            state = "" if not problems else "  NOT THE CPU IT SHOULD BE: " + "; ".join(problems)
            self.tally.say(
                f"{machine.name:10} {about.get('machine')}, Python {about.get('python')}, numpy "
                f"{about.get('numpy')} finds {simd}{state}"
            )

    def say_compiled(self, machine: Machine, done: dict[str, Any], part: int) -> None:
        compiled = done.get("compiled", [])
        if compiled and part == 0:
            shown = ", ".join(compiled[:4]) + (", ..." if len(compiled) > 4 else "")
            self.tally.say(f"{machine.name:10} ran {len(compiled)} compiled modules: {shown}")

    def judge(self, machine: Machine, line: dict[str, Any]) -> None:
        job = self.by_key[line["key"]]
        label = f"{machine.name:10} {job.key:44}"
        if "error" in line:
            last = line["error"].strip().splitlines()[-1]
            self.tally.add(False, f"{machine.name} {job.key}: {last}")
            self.tally.say(f"{label} ERROR {last}")
            return
        run = line.get("run")
        name = run["digest"] if run else record_hash(line["record"])
        notes = []
        if machine.name == "native":
            self.native[job.key] = line
        else:
            self.native_done.wait()
            native = self.native.get(job.key)
            if native is None or "error" in native:
                same = self.tally.add(False, f"{machine.name} {job.key}: no native result")
                notes.append("no native result")
            else:
                same = self.tally.add(
                    native["record"] == line["record"] and native["run"] == line["run"],
                    f"{machine.name} {job.key}: differs from the native run: "
                    + "; ".join(self.differences(native, line)),
                )
                notes.append("same as native" if same else "DIFFERS from native")
        if job.published is not None:
            now = published.published_form(job, line["record"])
            differs = published.differences(job.published, now)
            self.tally.add(
                not differs,
                f"{machine.name} {job.key}: differs from the published "
                "record: " + "; ".join(differs[:4]),
            )
            notes.append("as published" if not differs else "DIFFERS from published")
        self.tally.say(
            f"{label} {name}  {', '.join(notes) or 'no published record'}  {line['seconds']:.1f} s"
        )

    @staticmethod
    def differences(native: dict[str, Any], now: dict[str, Any]) -> list[str]:
        found = []
        for part in ("run", "record"):
            if native[part] != now[part]:
                changed = published.differences(native[part], now[part])
                found.append(f"{part}: " + "; ".join(changed[:4]))
        return found

    # --- the C robot ------------------------------------------------------------------

    def c_robot(self, seed: int) -> None:
        say, add = self.tally.say, self.tally.add
        try:
            build = c_robot.cross()
            problems = c_robot.flags(build)
        except SetupError as error:
            add(False, f"C robot: {error}")
            say(f"c-robot    FAILED: {error}")
            return
        add(not problems, "C robot: the cross build's flags: " + "; ".join(problems[:3]))
        say(
            f"c-robot    {build.target}: compile flags "
            + ("-ffp-contract=off, no -march" if not problems else "WRONG: " + problems[0])
        )
        tests = c_robot.unit_tests(build)
        ok = tests.failed == 0 and tests.passed > 0 and tests.key_files.endswith(" 0 failed")
        add(ok, f"C robot: unit tests under qemu: {tests.failed} failed ({tests.output[-300:]})")
        say(
            f"c-robot    unit tests under {' '.join(build.emulator())}: {tests.passed} passed, "
            f"{tests.failed} failed ({tests.key_files})"
        )
        if not build.binary.exists():
            add(False, "C robot: no aarch64 program to run")
            return
        try:
            run = c_robot.lockstep(build, seed)
        except (RuntimeError, subprocess.SubprocessError, json.JSONDecodeError) as error:
            add(False, f"C robot: the lockstep run failed: {str(error)[-300:]}")
            say(f"c-robot    lockstep run FAILED: {str(error)[-200:]}")
            return
        same = run["same"] and run["programs_ended"] == len(c_robot.OUTSIDE)
        add(
            same,
            f"C robot: the UDP lockstep run (seed {seed}) gave {run['digest']}, the "
            f"all-emulated run {run['reference_digest']} ({run})",
        )
        say(
            f"c-robot    lockstep over UDP, robots {c_robot.OUTSIDE} in C on aarch64, seed {seed}: "
            f"{run['digest']} "
            + (
                "the same run as all emulated"
                if same
                else f"DIFFERS from all emulated ({run['reference_digest']})"
            )
        )

    # --- all of it ----------------------------------------------------------------------

    def run(self, with_c_robot: bool, c_robot_seed: int) -> None:
        native, emulated = self.machines[0], self.machines[1:]
        parts = [
            (machine, group, index)
            for machine in emulated
            for index, group in enumerate(chunks(self.jobs, self.workers))
        ]
        parts.sort(key=lambda part: -sum(job.seconds for job in part[1]))
        pool = concurrent.futures.ThreadPoolExecutor(max_workers=self.workers)
        futures = [pool.submit(self.native_probe, native)]
        if with_c_robot:
            futures.append(pool.submit(self.c_robot, c_robot_seed))
        futures += [pool.submit(self.probe, *part) for part in parts]
        try:
            for future in futures:
                future.result()
        finally:
            # Interrupted (or failed): what has not started never starts, and every probe
            # still running is stopped; a step of the C robot's ends by its own timeout.
            self.stopping = True
            self.native_done.set()
            pool.shutdown(wait=False, cancel_futures=True)
            for process in self.processes:
                if process.poll() is None:
                    process.kill()

    def native_probe(self, machine: Machine) -> None:
        try:
            self.probe(machine, self.jobs, 0)
        finally:
            self.native_done.set()


def stopped(number: int, frame: object) -> None:
    """SIGTERM: stop as on Ctrl-C (the probes started are stopped)."""
    raise KeyboardInterrupt


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.sample < 0:
        parser.error("--sample must be 0 or more")
    if args.jobs < 1:
        parser.error("--jobs must be 1 or more")
    try:
        jobs = published.choose(args.sample, args.seed, args.runs, not args.sample_only)
    except KeyError as error:
        parser.error(f"--runs: no such run {error} (--list shows the keys of some)")
    except (OSError, ValueError) as error:
        parser.error(f"the published files cannot be read: {error}")
    if args.list:
        for job in jobs:
            # The key last: a study's keys hold spaces.
            print(f"{job.source:17} about {job.seconds:6.1f} s natively  {job.key}")
        return 0
    tally = Tally()
    names = list(dict.fromkeys(args.machines))
    tools = []
    if {"haswell", "nehalem"} & set(names):
        tools.append("qemu-x86_64")
    if set(AARCH64) & set(names) or not args.no_c_robot:
        tools.append("qemu-aarch64")
    if not args.no_c_robot:
        tools.append(c_robot.CROSS)
    cache = args.cache.resolve()
    try:
        machines.ensure_tools(tools, tally.say)
        chosen = [machines.native()]
        python = machines.Aarch64Python(cache / "aarch64")
        if set(AARCH64) & set(names):
            python.prepare(tally.say)
        for name in names:
            if name in AARCH64:
                chosen.append(python.machine(None if name == "aarch64" else name))
            else:
                chosen.append(machines.haswell() if name == "haswell" else machines.nehalem())
    except SetupError as error:
        print(f"check-portable: error: {error}", file=sys.stderr)
        return 2
    tally.say(
        f"{len(jobs)} run(s) on {', '.join(m.name for m in chosen)}; niceness "
        f"{os.nice(0)}, load {Path('/proc/loadavg').read_text().split()[0]}"
    )
    for machine in chosen[1:]:
        tally.say(f"{machine.name:10} {machine.title}")
    check = Check(jobs, chosen, cache, tally, args.jobs)
    signal.signal(signal.SIGTERM, stopped)
    try:
        check.run(not args.no_c_robot, args.c_robot_seed)
    except KeyboardInterrupt:
        print("check-portable: interrupted", file=sys.stderr)
        return 130
    elapsed = time.monotonic() - tally.started
    what = f"{len(jobs)} run(s) on {', '.join(machine.name for machine in chosen[1:])}"
    if not args.no_c_robot:
        what += " and the C robot on aarch64"
    if tally.failures:
        print("\nDifferences and failures:", flush=True)
        for failure in tally.failures:
            print(f"* {failure}")
        print(
            f"check-portable: {len(tally.failures)} of {tally.compared} comparisons FAILED "
            f"({what}), {elapsed:.0f} s"
        )
        return 1
    print(
        f"check-portable: all {tally.compared} comparisons matched ({what}: the native "
        f"results and the published records), {elapsed:.0f} s"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

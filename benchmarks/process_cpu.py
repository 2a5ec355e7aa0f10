"""Where a distributed swarm's CPU goes, process by process, against the in-process engine.

Runs ``swarm run`` (over Zenoh) with the given options and reads the CPU time (user and
system) of each of its processes from /proc every 50 ms while it runs: the world server,
the robot processes, the beacon, the recorder, the launcher. Then the same run stopped
after its first tick, to take away what starting and stopping cost, so what is left is
the CPU of ticking. Then the same computation in one process (``--engine inprocess``),
measured the same way, for comparison:

    .venv/bin/python benchmarks/process_cpu.py --robots 10
    .venv/bin/python benchmarks/process_cpu.py --robots 100 --timeout 100

Every option is passed to ``swarm run`` (``--no-record`` is added unless ``--record`` is
given; the in-process runs leave out the options of the processes' layout, such as
``--robots-per-process``), except ``--doc PATH``: write the table into PATH too, between
the generated-block markers that name this command (``deploy/section5.replace_block``), as
docs/performance.md holds it. A process's last 50 ms before it exits can be missed; they
are spent stopping.
"""

from __future__ import annotations

import json
import os
import platform
import subprocess
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
TICKS_PER_SECOND = os.sysconf("SC_CLK_TCK")
SAMPLE_EVERY = 0.05


def _stat(pid: int) -> tuple[int, float] | None:
    """(parent pid, CPU seconds) of a live process, or None if it is gone."""
    try:
        text = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    fields = text[text.rindex(")") + 2 :].split()
    return int(fields[1]), (int(fields[11]) + int(fields[12])) / TICKS_PER_SECOND


def _role(pid: int, parents: dict[int, int]) -> str:
    command = _command(pid)
    if not command:
        return "gone"
    if "forkserver" in command:  # its command line names every module it preloads
        parent = parents.get(pid)
        forked = parent is not None and "forkserver" in _command(parent)
        return "robot processes" if forked else "fork server"
    for module, role in (
        ("world_server.server", "world server"),
        ("world_server.recorder", "recorder"),
        ("nest_beacon", "beacon"),
        ("resource_tracker", "other"),
    ):
        if module in command:
            return role
    if "deploy.cli" in command or "/swarm" in command:
        return "launcher"
    return "other"


def _command(pid: int) -> str:
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode()
    except OSError:
        return ""


def run_cpu(options: list[str]) -> tuple[dict[str, float], dict[str, object]]:
    """CPU seconds per role of one ``swarm run --json``, and its summary."""
    command = [sys.executable, "-m", "deploy.cli", "run", "--json", "--quiet", *options]
    process = subprocess.Popen(command, cwd=REPO, stdout=subprocess.PIPE)
    cpu: dict[int, float] = {}
    roles: dict[int, str] = {}
    while process.poll() is None:
        stats = {}  # pid -> (parent pid, CPU seconds) of every process on the machine
        for entry in os.listdir("/proc"):
            if entry.isdigit() and (stat := _stat(int(entry))) is not None:
                stats[int(entry)] = stat
        parents = {pid: parent for pid, (parent, _) in stats.items()}
        children: dict[int, list[int]] = {}
        for pid, parent in parents.items():
            children.setdefault(parent, []).append(pid)
        stack = [process.pid]
        while stack:
            pid = stack.pop()
            stack.extend(children.get(pid, []))
            if pid in stats:
                cpu[pid] = stats[pid][1]
                # Named at every sample: until it execs, a new process still shows the
                # command line of the process that started it.
                role = _role(pid, parents)
                if role != "gone":
                    roles[pid] = role
        time.sleep(SAMPLE_EVERY)
    output = process.stdout.read() if process.stdout else b""
    if process.returncode not in (0, 5):  # 5: ended by --timeout, a result here
        raise SystemExit(f"swarm run {' '.join(options)} failed ({process.returncode})")
    by_role: dict[str, float] = {}
    for pid, seconds in cpu.items():
        role = roles.get(pid, "other")
        by_role[role] = by_role.get(role, 0.0) + seconds
    return by_role, json.loads(output)


# Options of the processes' layout: the in-process engine has no processes and refuses them.
ZENOH_ONLY = {"--robots-per-process": 1, "--no-batch": 0, "--spawn": 1}


def in_process_options(options: list[str]) -> list[str]:
    """``options`` without those of the processes' layout (ZENOH_ONLY)."""
    kept: list[str] = []
    skip = 0
    for option in options:
        if skip:
            skip -= 1
        elif option in ZENOH_ONLY:
            skip = ZENOH_ONLY[option]
        else:
            kept.append(option)
    return kept


def write_doc(path: Path, options: list[str], lines: list[str]) -> None:
    """Replace this command's generated block in ``path`` with ``lines``."""
    from deploy.reports.section5 import replace_block

    name = " ".join(options)
    command = f"benchmarks/process_cpu.py {name} --doc {path}"
    block = "\n".join(["```", f"$ {command}", *lines, "```"])
    try:
        text = replace_block(path.read_text(), name, block, command, "benchmarks/process_cpu.py")
    except ValueError as error:
        raise SystemExit(f"{path}: {error}") from None
    path.write_text(text)
    print(f"wrote the table into {path}")


def main() -> None:
    options = sys.argv[1:]
    if "-h" in options or "--help" in options:
        print(__doc__)
        return
    doc = None
    if "--doc" in options:
        at = options.index("--doc")
        if at + 1 >= len(options):
            print("process_cpu.py: --doc needs a file", file=sys.stderr)
            raise SystemExit(2)
        doc = Path(options[at + 1])
        del options[at : at + 2]
    asked = list(options)
    if "--record" not in options:
        options.append("--no-record")
    load_before = os.getloadavg()[0]
    whole, summary = run_cpu(options)
    dt = float(summary["config"]["dt"])  # type: ignore[index]
    first_tick = ["--timeout", str(dt)]
    start_stop, _ = run_cpu([*options, *first_tick])
    alone_options = [*in_process_options(options), "--engine", "inprocess"]
    in_process, alone = run_cpu(alone_options)
    in_process_start_stop, _ = run_cpu([*alone_options, *first_tick])
    sim = float(summary["sim_time_s"])  # type: ignore[arg-type]
    ticks = round(sim / dt)
    lines: list[str] = []
    lines.append(
        f"swarm run {' '.join(options)}: {sim:.1f} s of sim time ({ticks} ticks), "
        f"{summary['real_time_factor']}x real time over Zenoh, "
        f"{alone['real_time_factor']}x in one process"
    )
    lines.append(
        f"{'process':<26} {'CPU s (run)':>11} {'start/stop':>10} {'ticking':>8} {'ms/tick':>8}"
    )
    total = 0.0  # CPU seconds
    for role in sorted(whole, key=lambda name: -whole[name]):
        ticking = whole[role] - start_stop.get(role, 0.0)
        total += ticking
        lines.append(
            f"{role:<26} {whole[role]:>11.2f} {start_stop.get(role, 0.0):>10.2f} "
            f"{ticking:>8.2f} {1e3 * ticking / ticks:>8.2f}"
        )
    alone_ticking = sum(in_process.values()) - sum(in_process_start_stop.values())
    alone_ticks = round(float(alone["sim_time_s"]) / dt)  # type: ignore[arg-type]
    lines.append(
        f"{'all, over Zenoh':<26} {'':>11} {'':>10} {total:>8.2f} {1e3 * total / ticks:>8.2f}"
    )
    lines.append(
        f"{'all, in one process':<26} {sum(in_process.values()):>11.2f} "
        f"{sum(in_process_start_stop.values()):>10.2f} {alone_ticking:>8.2f} "
        f"{1e3 * alone_ticking / alone_ticks:>8.2f}"
    )
    lines.append(
        f"CPU per tick over Zenoh / in one process: "
        f"{(total / ticks) / (alone_ticking / alone_ticks):.1f}"
    )
    lines.append(
        f"({platform.machine()} Linux, {os.cpu_count()} cores, {time.strftime('%Y-%m-%d')}; "
        f"1-minute load average {load_before:.1f} before, {os.getloadavg()[0]:.1f} after)"
    )
    print("\n".join(lines))
    if doc is not None:
        write_doc(doc, asked, lines)


if __name__ == "__main__":
    main()

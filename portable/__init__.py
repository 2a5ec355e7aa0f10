"""``make check-portable``: published runs again on emulated CPUs (qemu-user), compared
with the machine's own runs and with the published files; and the C robot built for
aarch64, its unit tests and a lockstep run with it. docs/testing.md describes the check,
docs/kernel.md what it shows.

* ``published``: which runs are checked (chosen from the published files) and what each
  published file says about a run;
* ``probe``: runs a list of jobs in the interpreter it is started with (native, or under
  an emulator) and prints one JSON line per job;
* ``machines``: the emulated machines, and what each needs installed and cached;
* ``c_robot``: the C robot cross-built for aarch64, under qemu-aarch64;
* ``check``: the command (``python -m portable``);
* ``mcu``: ``make check-mcu`` (``python -m portable.mcu``), the C robot as Cortex-M4F
  firmware under qemu-system-arm.
"""

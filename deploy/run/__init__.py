"""``swarm run``, in modules along its seams: ``launcher`` (the command and its main
loop), ``supervisor`` (the processes and the launcher's session), ``follower`` (what they
publish, checked), ``faults``, ``recording`` (the handshake with the recorder),
``signals``, ``console`` (what it shows) and ``inprocess`` (``--engine inprocess``).

Its options and the plan made from them are ``deploy/run_options.py`` and
``deploy/run_plan.py``, outside this folder: ``swarm experiment`` checks its runs with
them, and tests/test_layering.py allows no folder to import one that imports it back.
How a run ends is ``wire/endings.py``.
"""

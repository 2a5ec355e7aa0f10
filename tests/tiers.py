"""The test tiers, in one place: every test module is in exactly one of them.

``FAST``: the tests of the pure layers (decision, pooling, the controller and its parts,
navigation, vision and camera, the wire vocabulary and its vectors, world, physics and
radio units, the Section 4 model, the layering). They start no process and open no socket
and no Zenoh session, and together take under 2 minutes on 2 cores. ``make test-fast``
(``pytest -m fast``) runs them; tests/conftest.py marks them ``fast`` and makes any of
their tests fail that starts a process or opens a socket or a Zenoh session.

``SLOW``: tests of fast modules left out of the fast tier for their time alone (whole
swarms on real physics), with why; ``make test`` runs them.

``FULL_ONLY``: the rest, with why, run by ``make test`` only (which also runs ``FAST``).

tests/test_tiers.py fails if a test module is in neither or both, if a fast module imports
what starts processes or talks to a network, or if ``SLOW`` names a test that is not there.
"""

from __future__ import annotations

FAST = frozenset(
    {
        "test_auth",
        "test_batch",
        "test_beacon_endpoint",
        "test_camera_vision",
        "test_clock",
        "test_controller",
        "test_coordinator",
        "test_decision",
        "test_defence",
        "test_docs",
        "test_equations",
        "test_follower_freshness",
        "test_fuzz",
        "test_guard",
        "test_inbox",
        "test_keyspace",
        "test_layering",
        "test_link",
        "test_names",
        "test_navigation",
        "test_numeric",
        "test_parking",
        "test_phases",
        "test_physics",
        "test_pooling",
        "test_pooling_controller",
        "test_ports_contract",
        "test_protocol_doc",
        "test_radio",
        "test_robot_endpoint",
        "test_settings",
        "test_tiers",
        "test_user_files",
        "test_vectors",
        "test_voting",
        "test_watchdog",
        "test_wellstirred",
        "test_wellstirred_voting",
        "test_world",
    }
)

SLOW = {
    "test_controller::test_a_hundred_robots_all_park_and_decide_in_one_process": (
        "100 robots to consensus: about 50 s"
    ),
    "test_navigation::test_ten_robots_keep_cycling_through_a_crowded_nest": (
        "two 10-robot swarms cycling through the nest: about 12 s"
    ),
    "test_parking::test_every_slot_stays_reachable_whoever_is_already_parked": (
        "up to 500 parked robots: about 11 s"
    ),
    "test_parking::test_robots_pressed_in_behind_the_wall_row_push_their_way_out": (
        "a crowd pushing out on real physics: about 7 s"
    ),
}

FULL_ONLY = {
    "test_attacks": "attacks live runs over Zenoh",
    "test_c_robot": "builds the C robot and runs swarms with it over UDP and serial links",
    "test_attacks_presence": "attacks live runs over Zenoh (presence and freshness)",
    "test_byzantine": "a real run with Byzantine robots",
    "test_endings": "starts swarms",
    "test_experiment": "runs `swarm experiment` in a process",
    "test_faults": "starts swarms with faults",
    "test_inprocess": "starts swarms to compare with the in-process engine",
    "test_multihost": "network namespaces and processes",
    "test_outside": "starts swarms with robots outside the emulator over UDP and serial links",
    "test_portable_runs": "swarms in fresh interpreters, with SIMD dispatch and without",
    "test_recording": "starts swarms and the recorder",
    "test_report": "runs `swarm report` in a process; plots",
    "test_flood_memory": "floods a live swarm and reads its processes' memory",
    "test_private_runs": "starts swarms, experiments and processes to check what they leave",
    "test_ending_rule": "in-process runs, and the signal numbers of the stop signals",
    "test_recording_reader": "writes recordings, whose metadata asks git and uname",
    "test_router": "starts Zenoh routers",
    "test_run_parts": "the launcher's parts, with a Zenoh session",
    "test_scale_doc": "in-process runs of up to 50 robots",
    "test_section5": "60 in-process runs",
    "test_secure": "starts secure swarms",
    "test_swarm": "starts swarms",
    "test_sweep": "worker processes and a Dask cluster on loopback, some of them killed",
    "test_trace": "starts a traced swarm",
    "test_udp_radio": "UDP sockets and robot processes",
    "test_viewer": "starts swarms, the viewer and a browser",
    "test_wellstirred_cli": "runs the installed command in a process",
    "test_zenoh_acl": "Zenoh sessions and processes",
}


def is_fast(module: str, test: str) -> bool:
    """Whether test function ``test`` of ``tests/<module>.py`` is in the fast tier."""
    return module in FAST and f"{module}::{test}" not in SLOW

"""The test tiers, in one place: every test module is in exactly one of them.

``FAST``: the tests of the pure layers (decision, pooling, the controller and its parts,
navigation, vision and camera, the wire vocabulary and its vectors, world, physics and
radio units, the Section 4 model, the layering). They start no process and open no socket
and no Zenoh session, and together take under 2 minutes on 2 cores. ``make test-fast``
(``pytest -m fast``) runs them; tests/conftest.py marks them ``fast`` and makes any of
their tests fail that starts a process or opens a socket or a Zenoh session.

``SLOW``: tests of fast modules left out of the fast tier for their time alone (whole
swarms on real physics), with why; ``make test`` runs them.

``FAST_TESTS``: tests of the other modules that start nothing: fast, and guarded as such.

``FULL_ONLY``: the rest, with why, run by ``make test`` only (which also runs ``FAST``).

``PUBLISHED``: tests that run published runs again to check them against today's code,
with why; ``make check-published`` runs them (``pytest --published``), ``make test`` does
not.

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
        "test_controller_doc",
        "test_controller_vectors",
        "test_coordinator",
        "test_decision",
        "test_defence",
        "test_docs",
        "test_effects",
        "test_equations",
        "test_frame_collector",
        "test_follower_freshness",
        "test_fuzz",
        "test_guard",
        "test_inbox",
        "test_keyspace",
        "test_kinds_spelled_once",
        "test_layering",
        "test_link",
        "test_names",
        "test_navigation",
        "test_numeric",
        "test_parking",
        "test_phases",
        "test_physics",
        "test_pooling",
        "test_plugins",
        "test_pooling_controller",
        "test_process_main",
        "test_portable_check",
        "test_ports_contract",
        "test_protocol_doc",
        "test_radio",
        "test_robot_endpoint",
        "test_settings",
        "test_study_cli",
        "test_study_frame",
        "test_study_grid",
        "test_study_pages",
        "test_study_results",
        "test_tiers",
        "test_user_files",
        "test_vectors",
        "test_voting",
        "test_watchdog",
        "test_wellstirred",
        "test_wellstirred_voting",
        "test_wilson",
        "test_world",
        "test_world_ending",
    }
)

SLOW = {
    "test_controller_vectors::test_the_file_is_what_the_generator_makes_from_its_runs": (
        "five in-process swarms of ten robots: about 3 s with the compiled cores, 8 s without"
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
    "test_api": "the public API's runs over Zenoh and sweeps on worker processes",
    "test_attacks": "attacks live runs over Zenoh",
    "test_fault_plugins": "runs swarms with faults in one process and over Zenoh",
    "test_robot_builder": "starts a world, a beacon and robots by hand over Zenoh, and a swarm",
    "test_c_robot": "builds the C robot and runs swarms with it over UDP and serial links",
    "test_conformance": "builds C robots and runs programs over UDP and serial links, and swarms",
    "test_attacks_presence": "attacks live runs over Zenoh (presence and freshness)",
    "test_byzantine": "a real run with Byzantine robots",
    "test_endings": "starts swarms",
    "test_experiment": "runs `swarm experiment` in a process",
    "test_faults": "starts swarms with faults",
    "test_inprocess": "starts swarms to compare with the in-process engine",
    "test_hosts": "a hand-started run and a Dask cluster of processes on loopback",
    "test_mcu": "builds the robot as firmware and runs it under qemu; a C robot without entropy",
    "test_frame": "in-process runs and a swarm over Zenoh, recorded; swarm frame in a process",
    "test_run_output": "runs swarm in processes and a swarm with faults",
    "test_multihost": "network namespaces and processes",
    "test_notebook": "runs the example notebook in a Jupyter kernel, with a sweep on processes",
    "test_plugin_runs": "plug-ins in swarms over Zenoh, robot-agent --link and studies",
    "test_outside": "starts swarms with robots outside the emulator over UDP and serial links",
    "test_portable_runs": "swarms in fresh interpreters, with SIMD dispatch and without",
    "test_compiled_cores": "swarms in fresh interpreters, compiled and from the source",
    "test_recording": "starts swarms and the recorder",
    "test_report": "runs `swarm report` in a process; plots",
    "test_flood_memory": "floods a live swarm and reads its processes' memory",
    "test_private_runs": "starts swarms, experiments and processes to check what they leave",
    "test_ending_rule": "in-process runs, and the signal numbers of the stop signals",
    "test_recording_reader": "writes recordings, whose metadata asks git and uname",
    "test_router": "starts Zenoh routers",
    "test_run_parts": "the launcher's parts, with a Zenoh session",
    "test_section5": "60 in-process runs",
    "test_secure": "starts secure swarms",
    "test_study_published": "makes published runs again, on worker processes",
    "test_study_runner": "makes, kills and resumes a tiny study on processes; a run over Zenoh",
    "test_swarm": "starts swarms",
    "test_sweep": "worker processes and a Dask cluster on loopback, some of them killed",
    "test_trace": "starts a traced swarm",
    "test_udp_radio": "UDP sockets and robot processes",
    "test_viewer": "starts swarms, the viewer and a browser",
    "test_wellstirred_cli": "runs the installed command in a process",
    "test_wheel": "builds a wheel, installs it in a venv and runs its commands in processes",
    "test_zenoh_acl": "Zenoh sessions and processes",
}


# Tests of FULL_ONLY modules that start nothing (their modules' other tests do): in the
# fast tier like the FAST modules, and guarded the same way.
FAST_TESTS = frozenset(
    {
        "test_byzantine::test_a_liar_broadcasts_certainty_of_its_site_every_trip_and_never_settles",
        "test_byzantine::test_a_liar_needs_its_site_and_a_site_of_the_world",
        "test_byzantine::test_a_one_hot_opinion_is_final_under_both_pooling_operators",
        "test_byzantine::test_a_report_rebuilding_a_summary_reads_the_byzantine_robots_from_the_config",
        "test_byzantine::test_a_silent_robot_pools_and_decides_but_never_broadcasts",
        "test_byzantine::test_an_inverted_robot_eliminates_the_better_site_of_the_same_pair",
        "test_byzantine::test_bad_switches_exit_with_code_2_and_one_line",
        "test_byzantine::test_consensus_and_its_time_are_the_honest_robots",
        "test_byzantine::test_robot_agent_refuses_bad_switches_with_code_2",
        "test_byzantine::test_swarm_experiment_passes_byzantine_and_kill_switches_on_to_each_run",
        "test_byzantine::test_switches_parse_and_print_back",
        "test_byzantine::test_the_default_liar_site_is_seeded_never_the_best_and_shared",
        "test_ending_rule::test_a_run_goes_on_until_a_condition_holds_and_each_limit_counts_when_reached",
        "test_ending_rule::test_each_ending_has_its_exit_code_and_an_interrupted_run_tells_the_signal",
        "test_ending_rule::test_the_ending_from_why_the_run_stopped_and_what_the_robots_decided",
        "test_ending_rule::test_the_help_has_one_row_per_exit_code_in_order",
        "test_ending_rule::test_the_in_process_engine_stops_on_a_signal_or_the_wall_limit_at_once",
        "test_ending_rule::test_the_stop_signals_have_their_posix_numbers",
        "test_ending_rule::test_when_conditions_coincide_the_first_in_the_rules_order_decides",
        "test_conformance::test_bad_arguments_exit_with_code_2_and_one_line",
        "test_endings::test_an_unwritable_recording_path_is_refused_before_anything_starts",
        "test_endings::test_the_help_documents_each_endings_exit_code",
        "test_experiment::test_bad_arguments_exit_with_code_2_and_one_line",
        "test_flood_memory::test_the_caps_table_states_a_cap_for_every_process",
        "test_inprocess::test_a_wall_time_limit_ends_the_run_as_a_wall_timeout",
        "test_inprocess::test_each_ending_has_swarm_runs_exit_code",
        "test_inprocess::test_what_it_cannot_honour_is_a_one_line_usage_error",
        "test_mcu::test_a_key_record_is_the_layout_the_firmware_reads",
        "test_recording::test_a_bad_niceness_is_a_usage_error",
        "test_recording::test_foxglove_channels_use_the_official_schemas",
        "test_recording::test_foxglove_messages_carry_the_required_fields_and_the_run",
        "test_recording::test_log_time_is_sim_time_and_publish_time_is_wall_time",
        "test_recording::test_metadata_holds_config_versions_seed_and_summary",
        "test_recording::test_nothing_published_is_missing_from_the_recording",
        "test_recording::test_one_channel_per_key_with_its_protocol_schema",
        "test_recording::test_the_launcher_waits_for_the_recorder_while_its_file_grows",
        "test_recording::test_the_recorder_yields_the_cpu_only_to_a_swarm_that_leaves_it_idle_time",
        "test_report::test_a_runs_digest_is_its_per_robot_results_and_nothing_else",
        "test_report::test_a_trail_keeps_at_most_its_limit_of_evenly_spaced_points_and_the_last",
        "test_report::test_acks_are_expected_at_the_ticks_the_beacon_named",
        "test_run_parts::test_a_stop_signal_becomes_one_event_and_later_ones_change_nothing",
        "test_run_parts::test_faults_fall_due_in_sim_time_order_and_are_noted_as_the_summary_lists_them",
        "test_run_parts::test_stop_signals_that_come_while_the_lock_notify_takes_is_held_stop_the_process",
        "test_run_parts::test_the_inbox_takes_a_signal_whatever_else_filled_it",
        "test_run_parts::test_the_launcher_looks_with_its_clock_given_and_takes_a_signal_as_an_event",
        "test_run_parts::test_the_log_relay_holds_lines_for_the_recorder_and_publishes_none_once_detached",
        "test_section5::test_a_number_of_the_text_that_the_runs_do_not_give_is_named",
        "test_section5::test_a_runs_file_that_lacks_runs_or_has_other_settings_is_reported",
        "test_section5::test_blocks_are_replaced_between_their_markers",
        "test_section5::test_check_finds_a_run_that_changed",
        "test_section5::test_check_finds_an_edited_table_and_missing_data",
        "test_section5::test_check_runs_every_published_run_and_names_each_that_differs",
        "test_section5::test_cli_needs_the_repository",
        "test_section5::test_figure_data_is_what_the_tables_count",
        "test_section5::test_render_rewrites_the_blocks_from_the_published_runs",
        "test_section5::test_sample_goes_with_check",
        "test_section5::test_swarm_steps_is_the_last_robot_and_only_for_consensus",
        "test_section5::test_the_published_runs_file_holds_every_run_it_promises",
        "test_section5::test_the_sample_checks_seeds_0_to_9_and_says_what_it_did_not_check",
        "test_swarm::test_alpha_without_threshold_is_a_usage_error_not_a_traceback",
        "test_swarm::test_bad_arguments_exit_with_code_2_and_one_line",
        "test_swarm::test_every_component_prints_its_help",
        "test_sweep::test_dask_options_are_checked",
        "test_udp_radio::test_bad_options_are_refused_with_a_reason",
        "test_udp_radio::test_encode_frame_refuses_what_receivers_would_drop",
        "test_udp_radio::test_frame_layout_is_magic_version_sender_length_sender_payload",
        "test_viewer::test_a_forged_status_is_counted_and_never_reaches_the_page",
        "test_viewer::test_every_sample_passes_one_gate_that_rejects_what_is_not_a_valid_message",
        "test_viewer::test_foxglove_live_serves_the_recording_channels",
        "test_viewer::test_in_a_keyed_run_the_gate_checks_each_tag_with_its_speakers_key",
        "test_viewer::test_the_bridge_keeps_the_newest_state_and_a_bounded_list_of_deliveries",
        "test_wellstirred_cli::test_bad_arguments_exit_2_with_one_line",
        "test_wellstirred_cli::test_exact_mean_is_added_on_request",
        "test_wellstirred_cli::test_exact_mean_is_null_where_population_exceeds_the_pool",
        "test_wellstirred_cli::test_figures_are_written",
        "test_wellstirred_cli::test_json_is_one_array_with_the_documented_keys",
        "test_wellstirred_cli::test_same_seed_same_output",
        "test_wellstirred_cli::test_table_shows_baseline_and_k_star",
        "test_zenoh_acl::test_a_plan_refuses_names_that_would_clash_or_break_keys",
        "test_zenoh_acl::test_every_policy_names_existing_rules_and_one_subject_per_identity",
        "test_zenoh_acl::test_routers_connect_to_each_other_by_name",
        "test_zenoh_acl::test_the_templates_are_what_the_generator_writes",
    }
)

PUBLISHED = {
    "test_study_published::test_a_sample_of_the_published_runs_is_what_the_code_gives": (
        "makes a sample of every study's published runs again (swarm study NAME --check)"
    ),
}


def is_published(module: str, test: str) -> bool:
    """Whether test function ``test`` of ``tests/<module>.py`` checks published runs."""
    return f"{module}::{test}" in PUBLISHED


def is_fast(module: str, test: str) -> bool:
    """Whether test function ``test`` of ``tests/<module>.py`` is in the fast tier."""
    name = f"{module}::{test}"
    return (module in FAST and name not in SLOW) or name in FAST_TESTS

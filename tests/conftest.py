"""Shared fixtures: the packaged KUKA LWR 4+ and simulated experiments (seeded); every JSON
document pincal writes in a test is validated against ``docs/report.schema.json``."""

from __future__ import annotations

import argparse
import functools
import importlib
import json
import re
from pathlib import Path

import hypothesis
import jsonschema
import numpy as np
import pytest

from pincal.cli.parser import build_parser
from pincal.model.chain import KinematicChain
from pincal.model.dh.table import KUKA_LWR4_DH, TABLE2_LARGE
from pincal.robots import KUKA_FLANGE_LINK, kuka_lwr4plus_urdf
from pincal.simulation.cells import INDUSTRIAL_6R_START, INDUSTRIAL_6R_TABLE
from pincal.simulation.paper import SimulationSettings, simulate_experiment

# every property test draws the same examples on every run and in every worker, and none writes an example
# database (.hypothesis/) that parallel workers would share; a test's own settings add to these
hypothesis.settings.register_profile("pincal", derandomize=True, database=None)
hypothesis.settings.load_profile("pincal")


@pytest.hookimpl(tryfirst=True)
def pytest_cmdline_main(config):
    """A run of the suite or of a folder uses every core: pytest-xdist's ``-n auto``. Tests go to the
    workers one by one and an idle worker takes queued ones from a busy one (``--dist worksteal``): on a
    quiet 2-core machine the suite took 6 min 47 s so against 7 min 48 s with whole files per worker
    (``--dist loadfile``, which builds each module-scoped fixture once but leaves one worker idle while
    the other ends a long file). ``-n N`` or ``--dist`` given are kept; ``-n 0``, ``-p no:xdist``, a
    ``-k`` selection and a run of named files or tests stay in this process (starting the workers, ~2 s
    each, costs more than a few tests gain); ``--pdb`` runs in this process through xdist itself."""
    if not config.pluginmanager.hasplugin("xdist") or hasattr(config, "workerinput"):
        return
    whole_folders = all(Path(arg.split("::")[0]).is_dir() for arg in config.args)
    if config.option.numprocesses is None and whole_folders and not config.option.keyword:
        config.option.numprocesses = "auto"
        if config.option.dist == "no":
            config.option.dist = "worksteal"


@pytest.fixture(scope="session", autouse=True)
def _one_blas_thread():
    """One BLAS thread per test process, as pincal's commands run (pincal.cli.commands): the workers
    of a parallel run share the cores already, and a run gives the same numbers in one process or many."""
    import scipy.linalg  # noqa: F401  (threadpoolctl limits the libraries loaded: scipy's OpenBLAS too)
    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=1, user_api="blas"):
        yield


@pytest.fixture(scope="session")
def kuka_urdf():
    return kuka_lwr4plus_urdf()


@pytest.fixture
def kuka_chain(kuka_urdf):
    return KinematicChain.from_urdf(kuka_urdf, KUKA_FLANGE_LINK)


@pytest.fixture(scope="session")
def noisy_large_experiment(kuka_urdf):
    chain = KinematicChain.from_urdf(kuka_urdf, KUKA_FLANGE_LINK)
    settings = SimulationSettings(sigma_pos_mm=0.055, sigma_rot_deg=0.055, seed=3)
    return simulate_experiment(chain, KUKA_LWR4_DH, TABLE2_LARGE, settings)


SCHEMA_PATH = Path(__file__).resolve().parents[1] / "docs" / "report.schema.json"
#: The modules that write pincal's JSON documents, through their ``write_text``: REPORT.json and
#: evaluate --json (pincal.report.document), PLAN.json (pincal.planning.files).
DOCUMENT_WRITERS = ("pincal.report.document", "pincal.planning.files")
#: A document's kind in the schema (None: a REPORT.json, its top level) by a key only that kind has.
DOCUMENT_KINDS = {"report_version": None, "plan_version": "PlanJson", "not_held_out": "FixtureEvaluationJson",
                  "skipped_cpa_rows": "EvaluationJson", "camera_info": "CameraEvaluationJson",
                  "evaluated_targets": "TreeEvaluationJson"}
_validators: dict[str, jsonschema.protocols.Validator] = {}
#: Draft 2020-12, whose ``descend`` into a subschema that is only ``{"type": ...}`` checks the type in place
#: (:func:`_descend`). Most of a report's values are such leaves (the numbers of its arrays, its names and
#: units): the full descent builds a validator for each, about half of a validation's time (measured over 73
#: documents of six test files).
_Draft202012 = jsonschema.validators.extend(jsonschema.Draft202012Validator)
_full_descend = _Draft202012.descend


def _descend(self, instance, schema, *args, **kwargs):
    """``descend``, without building a validator for a value whose subschema is only ``{"type": ...}`` and
    which has that type: the full descent would run the ``type`` keyword alone, with the same type checker,
    and yield nothing. Anything else, a value of another type among them, takes the full descent (the same
    errors)."""
    if type(schema) is dict and len(schema) == 1 and "type" in schema:
        types = schema["type"]
        if any(self.is_type(instance, name) for name in ([types] if isinstance(types, str) else types)):
            return iter(())
    return _full_descend(self, instance, schema, *args, **kwargs)


_Draft202012.descend = _descend  # evolve() keeps the class: every subschema's validator descends so


def _validator(kind: str) -> jsonschema.protocols.Validator:
    """The validator of the schema's ``$defs`` entry ``kind``, built once per process."""
    if kind not in _validators:
        _validators[kind] = _Draft202012({"$ref": f"#/$defs/{kind}", "$defs": _schema()["$defs"]})
    return _validators[kind]


@functools.cache
def _schema() -> dict:
    """docs/report.schema.json, read once per process (callers only read it)."""
    return json.loads(SCHEMA_PATH.read_text(encoding="utf-8"))


def report_kinds() -> list[str]:
    """The kinds a REPORT.json may be: the schema's top level is ``oneOf`` their ``$ref``s."""
    return [entry["$ref"].rpartition("/")[2] for entry in _schema()["oneOf"]]


def validate_document(document, kind: str | None = None) -> None:
    """Raise ``jsonschema.ValidationError`` unless ``document`` is a REPORT.json (``kind`` None)
    or the document ``kind`` names in the schema's ``$defs`` (``EvaluationJson``, ``PlanJson`` …).

    A REPORT.json is checked against its own kind, the error naming the key, then against each other kind,
    which must refuse it: the schema's ``oneOf``, exactly one kind valid, without the ``oneOf`` keyword's
    full walk of every kind (which took twice the time of the rest, on a diagnose report)."""
    own = kind if kind is not None else report_kind(document)
    error = jsonschema.exceptions.best_match(_validator(own).iter_errors(document))
    if error is not None:
        raise error
    if kind is None:
        also = [other for other in report_kinds() if other != own and _validator(other).is_valid(document)]
        if also:
            raise jsonschema.ValidationError(f"a REPORT.json valid as {own} and as {also}: the schema's oneOf "
                                             f"accepts exactly one kind")


PACKAGE = Path(__file__).resolve().parents[1] / "pincal"


def package_files(package: Path = PACKAGE) -> list[Path]:
    """pincal's modules: the .py files of its packages (a folder with ``__init__.py``); the example
    scripts shipped as data in ``pincal/datasets/examples/`` are not modules of pincal."""
    return [p for p in sorted(package.rglob("*.py")) if (p.parent / "__init__.py").exists()]


def report_kind(document) -> str:
    """The kind of a REPORT.json, by its keys (the schema accepts exactly one)."""
    if "fixture" in document:
        return "FixtureReport"
    if "targets" in document:  # calibrate's and diagnose's with several --tip-link
        return "TreeReport"
    if document.get("measurement") == "camera":  # calibrate's and diagnose's with --camera-link
        return "CameraReport"
    if "diagnosis" in document:
        return "DiagnosisReport"
    return "PaperReport" if document.get("model") == "dh" else "CalibrationReport"


def document_kind(document) -> str | None:
    """The kind of a document pincal wrote (:data:`DOCUMENT_KINDS`); AssertionError if none."""
    kinds = [kind for key, kind in DOCUMENT_KINDS.items() if isinstance(document, dict) and key in document]
    assert len(kinds) == 1, f"not a document of docs/report.schema.json: keys {list(document)[:8]}"
    return kinds[0]


@pytest.fixture(autouse=True)
def _validate_written_documents(monkeypatch):
    """Every ``.json`` file the modules of :data:`DOCUMENT_WRITERS` write is validated as it is written."""
    for name in DOCUMENT_WRITERS:
        module = importlib.import_module(name)

        def checked(path, text, *args, _write=module.write_text, **kwargs):
            if str(path).endswith(".json"):
                document = json.loads(text)
                validate_document(document, document_kind(document))
            return _write(path, text, *args, **kwargs)

        monkeypatch.setattr(module, "write_text", checked)


def subcommand_actions() -> dict[str, dict[str, argparse.Action]]:
    """Each subcommand of ``pincal`` (:func:`pincal.cli.parser.build_parser`) and its actions by option string."""
    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    return {name: {flag: action for action in parser._actions for flag in action.option_strings}
            for name, parser in sub.choices.items()}


def unaccepted_flags(command: str, printed: str) -> list[str]:
    """The ``--flags`` that ``pincal COMMAND``'s output ``printed`` suggests and the command does not
    accept (a line naming another command — "pincal calibrate … --x", "calibrate with --x" — is that one's)."""
    actions = subcommand_actions()
    wrong = []
    for line in printed.splitlines():
        for match in re.finditer(r"(?<![\w-])(--[a-z][\w-]*)", line):
            before = line[:match.start()]
            named = re.findall(rf"\bpincal ({'|'.join(map(re.escape, actions))})\b|\b({'|'.join(actions)}) with $",
                               before)
            owner = next((a or b for a, b in reversed(named)), command) if named else command
            if match[1] not in actions[owner] and not re.search(r"\bpip install\b", before):
                wrong.append(f"{match[1]} ({owner}): {line.strip()[:160]}")
    return wrong


def said(stream: str, kind: str = "warning") -> list[str]:
    """What a command printed on ``stream`` as ``pincal: KIND: …`` lines (KIND ``warning`` or ``note``), the
    prefix removed: to compare with the ``warnings`` messages or ``notes`` of the REPORT.json it wrote, so a
    test checks that the console says what the report holds rather than a fragment of its wording."""
    prefix = f"pincal: {kind}: "
    return [line.removeprefix(prefix) for line in stream.splitlines() if line.startswith(prefix)]


def assert_close(actual, expected, atol, what=""):
    """Assert arrays are close and free of NaN (NaN never passes)."""
    actual = np.asarray(actual, dtype=float)
    expected = np.asarray(expected, dtype=float)
    assert actual.shape == expected.shape, f"{what}: shape {actual.shape} != {expected.shape}"
    assert np.all(np.isfinite(actual)), f"{what}: non-finite values"
    err = np.abs(actual - expected).max() if actual.size else 0.0
    assert err <= atol, f"{what}: max abs error {err:.3g} > {atol:.3g}"


def numeric_jacobian(fun, x, step=1e-6):
    """Central finite differences of ``fun`` at ``x``: columns stacked on the last axis."""
    columns = []
    for i in range(x.size):
        dx = np.zeros_like(x)
        dx[i] = step
        columns.append((fun(x + dx) - fun(x - dx)) / (2 * step))
    return np.stack(columns, axis=-1)


INDUSTRIAL_ARM_TABLE = INDUSTRIAL_6R_TABLE  # the unseen-setup tests' arm (pincal.simulation.cells)
INDUSTRIAL_ARM_START = INDUSTRIAL_6R_START


@pytest.fixture(scope="session")
def industrial_arm_urdf(tmp_path_factory):
    from pincal.model.dh.conversion import urdf_from_dh_table

    folder = tmp_path_factory.mktemp("industrial_arm")
    (folder / "arm.csv").write_text(INDUSTRIAL_ARM_TABLE, encoding="utf-8")
    urdf_from_dh_table(folder / "arm.csv", "modified", folder / "arm.urdf", degrees=True)
    return folder / "arm.urdf"


#: The inner loop leaves these out (``pytest -m "not slow"``, about a minute on two cores): tests that
#: took 0.45 s or more on the development machine (``pytest --durations``, 2026-11-27; an entry with
#: ``[id]`` marks that parametrisation only), the heaviest
#: parametrised ones, and whole files that run studies or start processes, a Dask cluster or a browser.
#: The full suite (CI, the README's command) runs them.
SLOW_FILES = (
    "tests/test_study.py",
    "tests/test_drift_span.py",
    "tests/test_html_report.py",
    "tests/test_study_dask_faults.py",
    "tests/test_study_processes.py",
)
SLOW_TESTS = (
    # whole-package scans and fresh interpreters (0.6-3 s each): the full suite and CI run them
    "tests/test_architecture.py::test_rooms_import_only_public_names",
    "tests/test_architecture.py::test_every_module_states_its_public_names",
    "tests/test_architecture.py::test_one_calibration_pipeline",
    "tests/test_flag_messages.py::test_every_flag_a_message_suggests_is_one_the_printing_command_accepts",
    "tests/test_public_api.py::test_star_import_in_a_fresh_interpreter",
    "tests/test_html_plan.py::test_one_colour_per_model_in_every_section",
    "tests/test_html_plan.py::test_percent_change_reads_minus_100_only_for_zero",
    "tests/test_prior_downstream.py::test_diagnose_report_gives_the_posterior_std",
    "tests/test_diagnosis.py::test_a_joint_read_against_another_is_named_and_corrected_in_the_data",
    "tests/test_read_against.py::test_a_joint_read_against_another_is_named_corrected_and_at_the_noise",
    "tests/test_mimic.py::test_calibrate_and_evaluate_without_the_column",
    # diagnose on a tree, end to end (3.5-4 s with its fixture) and with unknown masses (2.4 s)
    "tests/test_tree_diagnose.py::test_diagnose_names_the_torso_compliance_and_brings_each_target_to_the_noise_floor",
    "tests/test_tree_diagnose.py::test_without_the_effect_nothing_is_claimed_and_with_unknown_masses_its_moments"
    "[unknown]",
    # plan with several --tip-link: 32 tree calibrations against the plan's per-target prediction (11 s)
    "tests/test_tree_plan.py::test_planned_configurations_calibrate_as_predicted_for_each_target_and_beat_random",
    # diagnose --lateral on a tree, end to end (1.8 s with its fixture) and with unknown masses (0.8 s)
    "tests/test_tree_lateral.py::test_diagnose_lateral_names_the_torso_bending_and_evaluate_applies_it",
    "tests/test_tree_lateral.py::test_lateral_is_claimed_only_where_the_torso_bends[unknown-masses]",
    "tests/test_mimic.py::test_diagnose_names_a_wrong_multiplier",
    # diagnose through a camera, end to end: 28 images simulated and calibrated (2.3 s), and by the CLI (3 s)
    "tests/test_camera_diagnose.py::test_diagnose_names_the_backlash_and_the_held_out_images_reach_the_noise",
    "tests/test_camera_diagnose.py::test_cli_writes_the_effects_and_evaluate_applies_them",
    "tests/test_read_against.py::test_effects_that_correct_alike_are_applied_and_the_alternatives_named",
    "tests/test_tip_link.py::test_calibrate_and_plan_warn_on_a_short_tip",
    "tests/test_tip_link.py::test_diagnose_warns_on_a_short_tip",
    "tests/test_plausibility_gross.py::test_diagnose_withholds_a_gross_final_model_and_writes_a_corrected_one",
    "tests/test_plausibility_gross.py::test_a_residual_16_times_the_stated_noise_names_the_diagnose_command",
    "tests/test_cli_start.py::test_every_blas_the_run_loads_gets_one_thread",
    "tests/test_evaluate_console.py::test_diagnose_prints_the_point_rows_of_both_sets",
    "tests/test_evaluate_console.py::test_swapped_axes_warn_and_strict_exits_3_with_the_json_written",
    "tests/test_crawling_fits.py::test_a_candidate_whose_naming_fit_crawls_is_named_absorbed",
    "tests/test_crawling_fits.py::test_the_data_scale_fit_of_a_prior_calibration_stops_at_its_budget",
    "tests/test_couplings.py::test_diagnose_corrects_it_itself_and_the_flag_brings_the_model_to_the_noise",
    "tests/test_couplings.py::test_a_wrong_factor_given_is_named_with_the_one_that_fits",
    "tests/test_effects_file.py::test_calibrate_writes_couplings_only_and_a_plain_run_removes_its_stale_file",
    "tests/test_effects_file.py::test_diagnose_writes_what_the_urdf_cannot_carry_and_it_reads_back_as_the_report",
    "tests/test_level_choice.py::test_cli_fixture_level_auto_holds_out_each_placement",
    "tests/test_placement_check.py::test_strict_calibrate_exits_3_on_the_warning_with_every_output_written",
    "tests/test_placement_check.py::test_strict_evaluate_exits_3_on_a_held_out_placement_predicted_worse",
    "tests/test_diagnosis.py::test_undeclared_effect_is_found_measured_and_removed",
    "tests/test_lateral.py::test_a_lateral_and_a_joint_compliance_that_correct_alike_are_both_named",
    "tests/test_lateral.py::test_a_lateral_compliance_without_masses_is_named_and_the_heldout_error_reaches_the_noise",
    "tests/test_lateral.py::test_effects_yaml_carries_the_lateral_compliances_evaluate_applies",
    "tests/test_diagnosis.py::test_evaluate_on_interleaved_rows_takes_the_flanks_diagnose_fitted",
    "tests/test_effect_units.py::test_a_lift_sagging_under_the_shoulders_torque_is_stated_in_m_per_newton_metre",
    "tests/test_selection.py::test_tiago_selection_is_that_of_refitting_every_subset",
    "tests/test_fixture.py::test_noise_free_data_recover_the_robot",
    "tests/test_fixture.py::test_example_reproduces_the_readme_iiwa_rows",
    "tests/test_docs.py::test_mkdocs_build_strict",
    "tests/test_chain_calibration.py::test_noisy_heldout_error_matches_noise_limited_prediction",
    "tests/test_line_hold.py::test_one_line_end_to_end_calibrate_diagnose_and_evaluate",
    "tests/test_line_hold.py::test_moving_the_sensor_changes_nothing",
    "tests/test_line_hold.py::test_one_arc_at_constant_orientation_predicts_the_path",
    "tests/test_chain_values.py::test_the_level_choice_and_diagnose_leave_the_chain",
    "tests/test_continuous_joints.py::test_every_serial_chain_of_example_robot_data_is_recovered",
    "tests/test_continuous_joints.py::test_kinova_calibrate_and_evaluate",
    "tests/test_continuous_joints.py::test_kinova_diagnose",
    "tests/test_continuous_joints.py::test_kinova_plan",
    "tests/test_diagnosis.py::test_diagnose_command_writes_effects_that_evaluate_applies",
    "tests/test_diagnosis.py::test_rounding_level_effects_are_not_adopted",
    "tests/test_diagnosis.py::test_screening_refits_every_candidate_that_matters",
    "tests/test_diagnosis.py::test_tiago_diagnose_beats_the_geometric_calibration",
    "tests/test_thermal.py::test_hidden_expansion_is_named_measured_and_removed",
    "tests/test_thermal.py::test_evaluate_holds_a_row_beyond_the_fitted_range_at_its_end",
    "tests/test_thermal.py::test_hidden_pause_step_is_named_not_drift_and_removed",
    "tests/test_thermal.py::test_clean_data_adopt_neither_and_missing_columns_are_named",
    "tests/test_fold_update.py::test_linearised_folds_agree_with_refits",
    "tests/test_frame_invariance.py::test_a_target_offset_changes_only_the_target",
    "tests/test_frame_invariance.py::test_moving_the_sensor_frame_changes_nothing",
    "tests/test_fuzz_readers.py::test_cli_subprocess_broken_urdf_one_line_no_traceback",
    "tests/test_level_choice.py::test_cli_calibrate_level_auto_reports_and_prints_the_choice",
    "tests/test_level_choice.py::test_cli_diagnose_level_auto",
    "tests/test_level_choice.py::test_cli_level_auto_with_an_explicit_select_keeps_it",
    "tests/test_level_choice.py::test_noise_free_full_level_deviations_choose_full",
    "tests/test_level_choice.py::test_sparse_noisy_data_from_offset_errors_choose_offsets",
    "tests/test_level_choice.py::test_tiago_level_auto_under_the_prior_is_within_ten_percent_of_the_best_fixed_level",
    "tests/test_ml_estimator.py::test_ml_beats_method2_at_the_paper_noise",
    "tests/test_ml_estimator.py::test_only_the_sigma_ratio_changes_the_estimate",
    "tests/test_noise_limit.py::test_monte_carlo_errors_match_the_prediction",
    "tests/test_outputs.py::test_every_write_of_pincal_goes_through_outputs",
    "tests/test_outputs.py::test_killed_calibrate_leaves_old_or_whole_outputs",
    "tests/test_outputs.py::test_killed_study_leaves_old_or_whole_outputs",
    "tests/test_plan.py::test_alternate_order_balances_the_approach_directions",
    "tests/test_plan.py::test_cli_plans_writes_the_plan_and_its_prediction",
    "tests/test_plan.py::test_min_distance_refuses_configurations_closer_than_the_clearance",
    "tests/test_plan.py::test_planned_configurations_calibrate_as_predicted_and_beat_random",
    "tests/test_plan.py::test_recorded_data_choose_additions_with_decreasing_predicted_error",
    "tests/test_plan.py::test_the_best_of_several_exchange_starts_is_kept",
    "tests/test_plan.py::test_tiago_planned_subset_is_in_the_best_quarter_of_random_subsets",
    "tests/test_plausibility.py::test_bad_data_warns_and_strict_exits_3_with_the_outputs_written",
    "tests/test_prior_downstream.py::test_cli_prior_scale_under_level_auto_needs_no_select",
    "tests/test_prior_scales.py::test_a_prismatic_joints_zero_is_a_length",
    "tests/test_prior_scales.py::test_prior_scale_fixes_the_scales",
    "tests/test_prior_scales.py::test_folds_at_scale_choose_their_scales_without_their_held_out_rows",
    "tests/test_progress.py::test_commands_report_progress_on_stderr_and_quiet_silences_it",
    "tests/test_scenarios.py::test_scenario_reaches_its_noise_floor",
    "tests/test_study_reference.py::test_study_rows_equal_those_of_6975758",
    "tests/test_target_hold.py::test_raster_at_constant_orientation_holds_the_target_and_reaches_the_noise_floor",
    "tests/test_urdf_elements.py::test_calibrate_imports_neither_yourdfpy_nor_plots_nor_other_commands",
    "tests/test_xacro.py::test_calibrate_xacro_end_to_end",
    "tests/test_extract.py::test_a_bag_reads_back_what_was_written",
    "tests/test_extract.py::test_static_postures_offset_and_refusals_are_recovered",
    "tests/test_extract.py::test_markers_as_points_topics_and_tf_frames_in_the_order_given",
    "tests/test_extract.py::test_bag_to_calibrate_to_evaluate_matches_the_csv_it_was_made_from",
    # one parametrisation each: the pages whose blocks take 0.45 s or more (README.md, commands.md stay)
    "tests/test_docs_examples.py::test_the_blocks_of_a_page_run_in_order[docs/diagnose.md]",
    "tests/test_docs_examples.py::test_the_blocks_of_a_page_run_in_order[docs/fixture.md]",
    "tests/test_docs_examples.py::test_the_blocks_of_a_page_run_in_order[docs/extract.md]",
    "tests/test_docs_examples.py::test_the_blocks_of_a_page_run_in_order[docs/plan.md]",
    "tests/test_docs_examples.py::test_the_blocks_of_a_page_run_in_order[docs/getting-started.md]",
    "tests/test_docs_examples.py::test_the_blocks_of_a_page_run_in_order[docs/whole-robots.md]",
    # diagnose --lateral on the four-joint torso without inertias, by the CLI (4 s CPU with its fixture), evaluate
    # of its report (1 s) and the rigid robot's diagnose (1.6 s)
    "tests/test_torso_compliance.py::test_diagnose_names_the_shoulder_and_the_sideways_bending_without_masses",
    "tests/test_torso_compliance.py::test_each_hand_held_out_at_the_noise_floor_and_evaluate_applies_the_effects",
    "tests/test_torso_compliance.py::test_without_the_compliances_nothing_is_claimed",
)


#: The files whose longest test takes 4 s or more on a quiet 2-core machine under xdist, longest first
#: (``pytest --durations``, 2026-11-29: docs/diagnose.md's page ~30 s ... the HTML plan ~4 s). A parallel
#: run starts them first: each worker takes its tests from the front of its queue and an idle one steals
#: from the back of another's, so the run ends on quick tests rather than idling a worker through a long
#: one that happened to come last. Whole files move, in their own order, so a module-scoped fixture is
#: still built once per worker. The order decides only when a test runs: a stale list costs seconds.
LONGEST_FIRST = (
    "tests/test_docs_examples.py",
    "tests/test_study_processes.py",
    "tests/test_plan.py",
    "tests/test_tree_plan.py",
    "tests/test_crawling_fits.py",
    "tests/test_study.py",
    "tests/test_html_report.py",
    "tests/test_study_dask_faults.py",
    "tests/test_progress.py",
    "tests/test_fold_update.py",
    "tests/test_outputs.py",
    "tests/test_docs.py",
    "tests/test_thermal.py",
    "tests/test_line_hold.py",
    "tests/test_level_choice.py",
    "tests/test_frame_invariance.py",
    "tests/test_plausibility_gross.py",
    "tests/test_tip_link.py",
    "tests/test_drift_span.py",
    "tests/test_extract.py",
    "tests/test_scenarios.py",
    "tests/test_study_reference.py",
    "tests/test_target_hold.py",
    "tests/test_effects_file.py",
    "tests/test_flag_messages.py",
    "tests/test_evaluate_console.py",
    "tests/test_xacro.py",
    "tests/test_html_plan.py",
    "tests/test_torso_compliance.py",
)


def pytest_collection_modifyitems(config, items):
    for item in items:
        path, _, name = item.nodeid.partition("::")
        if path in SLOW_FILES or f"{path}::{name.split('[')[0]}" in SLOW_TESTS or item.nodeid in SLOW_TESTS:
            item.add_marker(pytest.mark.slow)
    if hasattr(config, "workerinput"):  # a worker of a parallel run: every worker collects the same order
        rank = {path: number for number, path in enumerate(LONGEST_FIRST)}
        items.sort(key=lambda item: rank.get(item.nodeid.partition("::")[0], len(rank)))  # stable

"""One name per setting: each option of ``run`` is named after the parameter it sets (tests of the convention).

The convention: a ``run`` option is the name of the PipelineConfig field (or of the ``load_dataset`` / ``write_run``
parameter) it sets, with ``_`` -> ``-`` and a trailing unit suffix (``_px``, ``_s``) dropped; a boolean that is on by
default is switched off with ``--no-NAME``. The exceptions are listed below, each with its reason.
"""
import argparse
import dataclasses
import inspect

from evio_lib.pipeline.command import _OPTIONS, add_run_arguments
from evio_lib.pipeline.dataset import load_dataset
from evio_lib.pipeline.output import write_run
from evio_lib.pipeline.run import PipelineConfig

#: ``run`` options that set no parameter of the same name, and why.
OPTION_EXCEPTIONS = {
    "dataset": "positional: load_dataset's first parameter, DATASET",
    "--weights": "an entry ('weights', PATH) of PipelineConfig.detector_options, the detector's own name for it",
    "--cnn-inference": "an entry ('inference', MODE) of PipelineConfig.detector_options; 'cnn-' since only the CNN "
                       "detectors have it",
    "--adaptive": "PipelineConfig.adaptive_windows: the same switch as `reconstruct --adaptive`, one name for both "
                  "commands",
    "--threads": "a process setting (evio_lib.threads.set_threads), no parameter of the run",
    "--quiet": "the negation of run_pipeline's and load_dataset's progress=True, the usual name of that switch",
    "--verbose": "what the command prints (the notes whole, the settings, times, dropped tracks), not a run setting",
}
#: PipelineConfig fields that no ``run`` option sets by their own name, and why.
FIELD_EXCEPTIONS = {
    "detector_options": "set by --weights and --cnn-inference (above)",
    "adaptive_windows": "set by --adaptive (above)",
    "match_ratio": "Python only: the pipeline matches without a ratio test (docs/archive.md, Lowe's ratio rows)",
}
UNIT_SUFFIXES = ("_px", "_s")


def option_name(parameter: str, default=None) -> str:
    """Return the option the convention gives a parameter (``--no-NAME`` for a boolean on by default)."""
    for suffix in UNIT_SUFFIXES:
        if parameter.endswith(suffix):
            parameter = parameter[:-len(suffix)]
            break
    name = parameter.replace("_", "-")
    return f"--no-{name}" if default is True else f"--{name}"


def _parameters() -> dict[str, object]:
    """{name: default} of the PipelineConfig fields and the parameters of load_dataset and write_run (None: none)."""
    names = {f.name: f.default for f in dataclasses.fields(PipelineConfig)}
    for function in (load_dataset, write_run):
        for p in inspect.signature(function).parameters.values():
            if p.name not in ("result", "data"):  # write_run's run, not settings
                names.setdefault(p.name, None if p.default is inspect.Parameter.empty else p.default)
    return names


def _run_options() -> list[str]:
    parser = argparse.ArgumentParser()
    add_run_arguments(parser)
    options = []
    for action in parser._actions:
        if isinstance(action, argparse._HelpAction):
            continue
        long = [o for o in action.option_strings if o.startswith("--")]
        assert len(long) <= 1, action.option_strings  # one name per option: no aliases
        options.append(long[0] if long else action.dest)
    return options


def test_every_run_option_is_named_after_the_parameter_it_sets():
    by_option = {option_name(name, default): name for name, default in _parameters().items()}
    unnamed = [option for option in _run_options()
               if option not in by_option and option not in OPTION_EXCEPTIONS]
    assert unnamed == [], f"options that follow no parameter's name: {unnamed}"
    stale = sorted(set(OPTION_EXCEPTIONS) - set(_run_options()))
    assert stale == [], f"exceptions for options that no longer exist: {stale}"


def test_every_pipeline_config_field_has_its_option():
    options = set(_run_options())
    fields = {f.name: f.default for f in dataclasses.fields(PipelineConfig)}
    missing = [name for name, default in fields.items()
               if option_name(name, default) not in options and name not in FIELD_EXCEPTIONS]
    assert missing == [], f"PipelineConfig fields without the option of their name: {missing}"
    assert sorted(set(FIELD_EXCEPTIONS) - set(fields)) == []


def test_the_message_map_follows_the_convention():
    """``_OPTIONS`` turns a config's field name in an error message into the option the user typed."""
    parameters = _parameters()
    options = set(_run_options())
    for name, option in _OPTIONS.items():
        assert name in parameters, name
        assert option == option_name(name) and option in options, (name, option)


def test_former_names_are_gone():
    """No alias keeps a former name alive (the changelog lists the renames)."""
    parser = argparse.ArgumentParser()
    add_run_arguments(parser)
    for old in ("--no-oc", "--outlier-px", "--aps-blur-noise"):
        assert old not in parser._option_string_actions
    assert not hasattr(PipelineConfig(), "oc")


def test_the_renamed_options_reach_the_config(monkeypatch):
    """--no-observability-constrained, --observation-outlier and --far-points set their fields (the run stops before
    loading the recording)."""
    import pytest

    from evio_lib.pipeline import command, dataset, run

    class Stop(Exception):
        pass

    def stop(*args, **kwargs):
        raise Stop

    configs = []
    real = run.PipelineConfig
    monkeypatch.setattr(run, "PipelineConfig", lambda **kw: configs.append(real(**kw)) or configs[-1])
    monkeypatch.setattr(dataset, "load_dataset", stop)
    monkeypatch.setattr(run, "set_threads", lambda threads: None)  # this process keeps its settings
    parser = argparse.ArgumentParser()
    add_run_arguments(parser)
    for argv, expected in ((["boxes_like"], (True, None, False)),
                           (["boxes_like", "--no-observability-constrained", "--observation-outlier", "3",
                             "--far-points"], (False, 3.0, True))):
        with pytest.raises(Stop):
            command.main_run(parser.parse_args(argv + ["--quiet"]))
        config = configs[-1]
        assert (config.observability_constrained, config.observation_outlier_px, config.far_points) == expected


def test_features_default_to_each_trackers_own_and_a_named_detector_is_used_by_klt_too():
    """features None: SIFT for the descriptor tracker, FAST for KLT; a name given is used by KLT as well (it used to
    turn 'sift' into FAST silently)."""
    from evio_lib.pipeline.run import PipelineConfig

    assert PipelineConfig().frontend_config().detector_name == "sift"
    assert PipelineConfig(tracker="klt").frontend_config().detector_name == "fast"
    assert PipelineConfig(tracker="klt", features="sift").frontend_config().detector_name == "sift"
    fused = PipelineConfig(frames="aps+mc-events", event_tracker="klt")
    assert [fused.frontend_config(s).detector_name for s in ("aps", "mc-events")] == ["sift", "fast"]
    assert PipelineConfig(tracker="klt").label() == PipelineConfig(tracker="klt", features="fast").label()


def test_a_default_run_shortens_only_the_start_notes_and_never_a_file_name():
    from evio_lib.pipeline.command import plain_note

    start = ("start: the recording moves in its first 1 s (the gyro ranges over 0.41 rad/s and the accelerometer over "
             "2.66 m/s^2): the filter starts from the ground truth's pose and velocity")
    assert plain_note(start) == ("start: the recording moves in its first 1 s: the filter starts from the ground "
                                 "truth's pose and velocity")
    for kept in ("extrinsics: from runs/camchain (1).yaml", "camera: from --calib calib (2).txt",
                 "motion: the preset's played at speed 2 (rates x 2, accelerations x 4; its whole motion lasts 30 s)",
                 "scored over the overlap with the ground truth: 40 of 48 frames (truth [0.000, 1.600] s)"):
        assert plain_note(kept) == kept

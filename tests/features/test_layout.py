"""The features package's layout (issue 26): the former flat module names still import, as the same module objects,
with every name they offered; the registry, the configs, the weights and the caches are found where they were."""
import importlib
from pathlib import Path

import pytest

FORMER = {"superpoint": "network", "train": "training.train", "train_options": "training.options",
          "losses": "training.losses", "metrics": "training.metrics", "datasets": "training.datasets",
          "augment": "training.augment", "shapes": "training.shapes", "adaptation": "training.adaptation",
          "benchmark": "evaluation.benchmark", "benchmark_options": "evaluation.options",
          "evaluate": "evaluation.evaluate", "hpatches": "evaluation.hpatches"}

# evio_lib.features.superpoint, now split over the modules of evio_lib.features.network: its __all__ and its private
# helpers (tests and benches use a few), all still reachable from the former name.
SUPERPOINT_ALL = ["CELL", "MODEL_CONFIGS", "DEFAULT_WEIGHTS", "WEIGHTS_DIR", "TRAINING_COMMAND", "INFERENCE_MODES",
                  "SuperPointNet", "build_model", "count_parameters", "pad_to_cells", "logits_to_heatmap",
                  "nms_heatmap", "extract_keypoints", "refine_keypoints", "sample_descriptors", "postprocess",
                  "calibration_images", "quantize_int8", "inference_model", "save_checkpoint", "load_checkpoint",
                  "load_model", "resolve_weights", "shipped_weights", "SuperPointDetector"]
SUPERPOINT_PRIVATE = ["_POOL_AFTER", "_CHECKPOINT_FORMAT", "_check_input", "_conv_block", "_check_config",
                      "_check_logits", "_nms_numpy", "_nms_torch", "_check_tensor", "_quantization_modules",
                      "_cpu_flags", "_int8_engine", "_bf16_native", "_auto_mode", "_Int8SuperPoint", "_FastSuperPoint",
                      "_register_shipped_variants", "_check_count", "_check_real", "_check_image_shape",
                      "_check_device"]


@pytest.mark.parametrize("old,new", sorted(FORMER.items()))
def test_former_module_name_is_an_alias(old, new, check_former_module_name):
    check_former_module_name(f"evio_lib.features.{old}", f"evio_lib.features.{new}")


def test_the_split_superpoint_module_keeps_every_name():
    former = importlib.import_module("evio_lib.features.superpoint")
    assert sorted(former.__all__) == sorted(SUPERPOINT_ALL)
    missing = [name for name in SUPERPOINT_ALL + SUPERPOINT_PRIVATE if not hasattr(former, name)]
    assert not missing
    # each name is the object of the module that now defines it, not a copy
    assert former.SuperPointDetector is importlib.import_module("evio_lib.features.network.detector").SuperPointDetector
    assert former._auto_mode is importlib.import_module("evio_lib.features.network.inference")._auto_mode


def test_the_registry_names_the_new_modules():
    from evio_lib.features import base

    modules = {module for module, _ in base._BUILTIN_DETECTORS.values()} | set(base._PLUGIN_MODULES)
    assert not {m for m in modules if m.rsplit(".", 1)[1] in FORMER}  # no former name left in the registry
    for module, attribute in base._BUILTIN_DETECTORS.values():
        assert hasattr(importlib.import_module(module), attribute)
    for module in base._PLUGIN_MODULES:
        importlib.import_module(module)


def test_configs_weights_runs_and_cache_are_where_they_were(monkeypatch):
    """The move one folder down must not change where the training configs, the shipped weights, the training runs
    and the label cache are looked for."""
    from evio_lib.features.network.model import WEIGHTS_DIR
    from evio_lib.features.training.datasets import default_cache_dir
    from evio_lib.features.training.train import CONFIG_DIR, DEFAULT_CHECKPOINT_DIR, available_configs

    repository = Path(__file__).resolve().parents[2]
    assert CONFIG_DIR == repository / "evio_lib" / "features" / "configs"
    assert "magicpoint" in available_configs()
    assert WEIGHTS_DIR == repository / "evio_lib" / "weights"
    assert DEFAULT_CHECKPOINT_DIR == repository / "runs" / "features"
    monkeypatch.delenv("EVIO_CACHE_DIR", raising=False)
    assert default_cache_dir() == repository / "data" / "cache"

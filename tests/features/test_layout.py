"""The features package's layout: one name per module (the former flat names are gone, not aliased), the network's
public names offered by its package; the registry, the configs, the weights and the caches are found where they were."""
import importlib
from pathlib import Path

import pytest

FORMER = {"superpoint": "network", "train": "training.train", "train_options": "training.options",
          "losses": "training.losses", "metrics": "training.metrics", "datasets": "training.datasets",
          "augment": "training.augment", "shapes": "training.shapes", "adaptation": "training.adaptation",
          "benchmark": "evaluation.benchmark", "benchmark_options": "evaluation.options",
          "evaluate": "evaluation.evaluate", "hpatches": "evaluation.hpatches"}

# the public names of evio_lib.features.network (every module's __all__)
NETWORK_ALL = ["CELL", "MODEL_CONFIGS", "DEFAULT_WEIGHTS", "WEIGHTS_DIR", "TRAINING_COMMAND", "INFERENCE_MODES",
               "SuperPointNet", "build_model", "count_parameters", "pad_to_cells", "logits_to_heatmap",
               "nms_heatmap", "extract_keypoints", "refine_keypoints", "window_centroids", "sample_descriptors", "postprocess",
               "calibration_images", "quantize_int8", "inference_model", "save_checkpoint", "load_checkpoint",
               "load_model", "resolve_weights", "shipped_weights", "SuperPointDetector",
               "PYRAMID_LEVELS_ABOVE", "PYRAMID_MIN_SIDE", "PYRAMID_STEP", "check_scales", "merge_levels", "parse_scales", "pyramid_scales",
               "resize_level"]


@pytest.mark.parametrize("old,new", sorted(FORMER.items()))
def test_a_module_has_one_name(old, new):
    importlib.import_module(f"evio_lib.features.{new}")
    with pytest.raises(ModuleNotFoundError):
        importlib.import_module(f"evio_lib.features.{old}")


def test_the_network_package_offers_its_public_names_only():
    network = importlib.import_module("evio_lib.features.network")
    assert sorted(network.__all__) == sorted(NETWORK_ALL)
    assert network.SuperPointDetector is importlib.import_module("evio_lib.features.network.detector").SuperPointDetector
    assert not [name for name in vars(network) if name.startswith("_") and not name.startswith("__")]


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
    from evio_lib.io.cache import default_cache_dir
    from evio_lib.features.training.train import CONFIG_DIR, DEFAULT_CHECKPOINT_DIR, available_configs

    repository = Path(__file__).resolve().parents[2]
    assert CONFIG_DIR == repository / "evio_lib" / "features" / "configs"
    assert "magicpoint" in available_configs()
    assert WEIGHTS_DIR == repository / "evio_lib" / "weights"
    assert DEFAULT_CHECKPOINT_DIR == repository / "runs" / "features"
    monkeypatch.delenv("EVIO_CACHE_DIR", raising=False)
    assert default_cache_dir() == repository / "data" / "cache"

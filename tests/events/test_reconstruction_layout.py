"""The reconstruction package's layout: one name per module (the former flat names are gone, not aliased)."""
import importlib

import pytest

FORMER = {"reconstruction_nets": "nets", "reconstruction_data": "data", "reconstruction_train": "training",
          "reconstruction_train_options": "training_options", "reconstruction_eval": "evaluation",
          "reconstruct_command": "command"}


@pytest.mark.parametrize("old,new", sorted(FORMER.items()))
def test_a_module_has_one_name(old, new):
    importlib.import_module(f"evio_lib.events.reconstruction.{new}")
    with pytest.raises(ModuleNotFoundError):
        importlib.import_module(f"evio_lib.events.{old}")


def test_the_real_data_folder_is_beside_the_repository():
    """The move into the package must not change where the real recordings are looked for."""
    from pathlib import Path

    from evio_lib.events.reconstruction.evaluation import REAL_DATA

    repository = Path(__file__).resolve().parents[2]
    assert REAL_DATA == repository.parent / "shared" / "data" / "real"

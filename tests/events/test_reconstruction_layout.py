"""The reconstruction package's layout: the former flat module names still import, as the same module objects."""
import pytest

FORMER = {"reconstruction_nets": "nets", "reconstruction_data": "data", "reconstruction_train": "training",
          "reconstruction_train_options": "training_options", "reconstruction_eval": "evaluation",
          "reconstruct_command": "command"}


@pytest.mark.parametrize("old,new", sorted(FORMER.items()))
def test_former_module_name_is_an_alias(old, new, check_former_module_name):
    check_former_module_name(f"evio_lib.events.{old}", f"evio_lib.events.reconstruction.{new}")


def test_the_real_data_folder_is_beside_the_repository():
    """The move into the package must not change where the real recordings are looked for."""
    from pathlib import Path

    from evio_lib.events.reconstruction.evaluation import REAL_DATA

    repository = Path(__file__).resolve().parents[2]
    assert REAL_DATA == repository.parent / "shared" / "data" / "real"

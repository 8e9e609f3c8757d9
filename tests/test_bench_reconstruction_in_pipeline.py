"""The pure parts of bench/reconstruction_in_pipeline.py: its stretches, its seed checks and its ratio summary."""
import importlib.util
import math
from pathlib import Path

import pytest

_PATH = Path(__file__).resolve().parents[1] / "bench" / "reconstruction_in_pipeline.py"
_SPEC = importlib.util.spec_from_file_location("reconstruction_in_pipeline", _PATH)
bench = importlib.util.module_from_spec(_SPEC)
_SPEC.loader.exec_module(bench)


def test_extra_seeds_add_two_stretches_each_after_the_four_of_before():
    stretches = bench.stretches_for([5, 6])
    assert stretches[:4] == list(bench.STRETCHES)
    assert stretches[4:] == [("boxes_like", 5, 0.0, 8.0), ("aerial_like", 5, 0.0, 8.0),
                             ("boxes_like", 6, 0.0, 8.0), ("aerial_like", 6, 0.0, 8.0)]


@pytest.mark.parametrize("seeds, words", [([1, 5], "1: the test seeds"), ([4], "4: the seeds 3, 4 are run already"),
                                          ([5, 5], "5: each seed may be given once"), ([-1], "-1: seeds must be >= 0")])
def test_extra_seeds_that_are_not_new_validation_seeds_are_refused(seeds, words):
    assert words in bench.extra_seeds_problem(seeds)
    assert bench.extra_seeds_problem([5, 7]) is None


def test_extra_seeds_refused_on_the_command_line_with_one_line(capsys):
    with pytest.raises(SystemExit) as stop:
        bench.main(["--extra-seeds", "0"])
    assert stop.value.code == 2
    assert "error: --extra-seeds 0: 0: the test seeds" in capsys.readouterr().err


def test_ratio_summary_is_the_geometric_mean_and_its_standard_error():
    mean, error, low, high = bench.ratio_summary([2.0, 0.5])
    # ln ratios +-ln 2: mean 0, sample standard deviation sqrt(2) ln 2, standard error ln 2
    assert mean == pytest.approx(1.0) and error == pytest.approx(2.0) and (low, high) == (0.5, 2.0)
    assert bench.ratio_summary([1.5]) == pytest.approx((1.5, 1.0, 1.5, 1.5))
    ratios = [0.8, 1.1, 1.3, 2.0]
    logs = [math.log(r) for r in ratios]
    assert bench.ratio_summary(ratios)[0] == pytest.approx(math.exp(sum(logs) / 4))

"""Every package of evio_lib lists the names a student uses: ``dir(package)`` shows them and each one resolves.

The packages import their names on first use (``evio_lib.lazy_exports``), so importing a package stays cheap: checked
here in a fresh interpreter, where importing every package must not import torch (the command-line help and the
lessons before the networks do not need it).
"""
import importlib
import pkgutil
import subprocess
import sys

import pytest

import evio_lib

PACKAGES = sorted(f"evio_lib.{m.name}" for m in pkgutil.iter_modules(evio_lib.__path__) if m.ispkg)


@pytest.mark.parametrize("name", PACKAGES)
def test_every_package_lists_its_public_names_and_each_resolves(name):
    package = importlib.import_module(name)
    public = getattr(package, "__all__", None)
    assert public, f"{name} has no __all__: dir({name}) shows nothing a student can use"
    assert len(set(public)) == len(public)
    for attribute in public:
        assert attribute in dir(package)
        value = getattr(package, attribute)
        defined_in = getattr(value, "__module__", None)
        assert defined_in is None or defined_in.startswith(name) or not callable(value), (attribute, defined_in)


def test_the_homework_names_are_where_a_student_looks():
    from evio_lib.events import event_count_image
    from evio_lib.geometry import observation_covariance
    from evio_lib.io import write_tum
    from evio_lib.sim import SimulationConfig, simulate_feature_tracks

    assert all(callable(f) for f in (event_count_image, observation_covariance, write_tum, simulate_feature_tracks,
                                     SimulationConfig))


def test_importing_every_package_stays_light():
    code = ("import sys, importlib\n"
            f"for name in {PACKAGES!r}: importlib.import_module(name)\n"
            "print(sorted(m for m in ('torch', 'matplotlib') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"

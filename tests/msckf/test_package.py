"""The package ``evio_lib.msckf`` offers the names a student uses (``dir`` shows them, each is the submodule's object)
and imports them on first use: importing the package alone loads none of its submodules."""
import importlib
import subprocess
import sys

import evio_lib.msckf as msckf

#: what the lessons, the bench scripts and the examples import from the package's submodules, and the filter's parts
STUDENT_NAMES = (
    "Msckf", "MsckfConfig", "FilterOutput", "MsckfWarning", "FilterState", "ImuState", "initial_state_from_truth",
    "initial_state_from_static", "static_initialization", "run_vio_sim", "run_vio_sim_seeds", "run_vio_sim_config",
    "VioSimConfig", "whitening_matrices", "augment_state", "augmentation_jacobian", "propagate", "integrate_imu",
    "triangulate_inverse_depth", "triangulate_inverse_depth_batch", "feature_jacobians", "nullspace_project",
    "measurement_compress", "kalman_update", "chi_square_gate", "gating_mean_shrink", "state_nullspace",
    "camera_nullspace", "imu_nullspace", "constrain_transition", "constrain_projected_jacobian",
    "constrain_feature_jacobians", "remove_camera_states", "ZeroVelocityConfig", "ImuBuffer", "FeatureDatabase",
    "MsckfUpdater",
)


def test_dir_shows_the_student_names_and_each_is_the_submodules_object():
    assert set(STUDENT_NAMES) <= set(msckf.__all__) <= set(dir(msckf))
    assert len(set(msckf.__all__)) == len(msckf.__all__)
    for name in msckf.__all__:
        value = getattr(msckf, name)
        home = importlib.import_module(f"evio_lib.msckf.{msckf._EXPORTS[name]}")
        assert value is getattr(home, name), name
        assert getattr(value, "__module__", "evio_lib.msckf").startswith("evio_lib.msckf"), name
    from evio_lib.msckf import Msckf, MsckfConfig  # the package's names as a student writes them

    assert Msckf.__name__ == "Msckf" and MsckfConfig().max_camera_states == 40


def test_an_unknown_name_is_an_attribute_error():
    try:
        msckf.OC_UPDATE_MODES  # retired
    except AttributeError as error:
        assert "has no attribute 'OC_UPDATE_MODES'" in str(error)
    else:
        raise AssertionError("evio_lib.msckf.OC_UPDATE_MODES should not exist")


def test_importing_the_package_loads_no_submodule():
    code = ("import sys, evio_lib.msckf\n"
            "print(sorted(m for m in sys.modules if m.startswith('evio_lib.msckf.') or m in ('numpy', 'scipy', "
            "'torch')))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"

"""Readers and writers for real recording layouts (ECD text, EuRoC ASL, AEDAT4, TUM) and the npz cache.

The names a student uses are listed by ``dir(evio_lib.io)`` and imported on first use; the rest live in the
submodules.
"""
from __future__ import annotations

from evio_lib.lazy_exports import lazy_exports

#: name -> submodule of the names this package offers, imported on first use (PEP 562)
_EXPORTS = {
    "read_ecd": "ecd", "write_ecd": "ecd", "read_euroc": "euroc", "read_aedat4": "aedat4", "read_tum": "tum",
    "write_tum": "tum", "groundtruth_to_tum": "tum", "groundtruth_from_tum": "tum",
    "hamilton_BtoG_from_jpl_q_GtoB": "tum", "DataFileError": "errors", "atomic_output_dir": "output_dir",
    "check_output_dir": "output_dir", "default_cache_dir": "cache",
}
__all__ = list(_EXPORTS)
__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS, globals())

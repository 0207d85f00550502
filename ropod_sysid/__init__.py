"""ropod-sysid: identify the dynamic parameters of wheeled mobile robots from their logs.

The library follows the modular model of R.M. Beumer (MSc thesis, TU Eindhoven, 2021): the
platform base is the central body and every smart-wheel unit adds its contribution to the direct
equations of motion  M_dir q̈_b = B_Fb F_b + B_τ (τ + τ_fw) + B_τfp τ_fp + b_dir  (eq. 65).
"""

from ropod_sysid.errors import InputError
from ropod_sysid.platform import Platform, UnitSpec, load_platform

__version__ = "0.1.0"

__all__ = ["InputError", "Platform", "UnitSpec", "load_platform", "__version__"]

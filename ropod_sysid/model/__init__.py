"""The modular dynamic model: the base (:mod:`.base`), the wheel-unit types (:mod:`.units`:
:mod:`.units.swivel`, :mod:`.units.omni`) and their sum (:mod:`.assembly`)."""

from ropod_sysid.model.assembly import DirectEOM, PlatformModel, State
from ropod_sysid.model.units.omni import OmniUnits
from ropod_sysid.model.units.swivel import SwivelUnits

__all__ = ["DirectEOM", "OmniUnits", "PlatformModel", "State", "SwivelUnits"]

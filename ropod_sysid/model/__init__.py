"""The modular dynamic model: the base (:mod:`.base`), wheel units (:mod:`.swivel`) and their
sum (:mod:`.assembly`)."""

from ropod_sysid.model.assembly import DirectEOM, PlatformModel, State
from ropod_sysid.model.swivel import SwivelUnits

__all__ = ["DirectEOM", "PlatformModel", "State", "SwivelUnits"]

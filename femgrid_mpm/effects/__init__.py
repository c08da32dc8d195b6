"""Effects a scene can declare; the step runs only the ones it declares.

Registry: scene ``kind`` -> class.  See :mod:`femgrid_mpm.effects.base` for
the protocol and the stages.
"""

from ..step import Stage, StepContext
from .contact import Contact
from .damping import MassDamping
from .gravity import Gravity
from .point_load import PointLoad
from .supports import Support

LOADS = {"point": PointLoad, "gravity": Gravity}
DAMPING = {"mass": MassDamping}

__all__ = ["Contact", "DAMPING", "LOADS", "Gravity", "MassDamping", "PointLoad", "Stage", "StepContext", "Support"]

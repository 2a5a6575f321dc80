"""Parameter pieces that several steps declare alike (pydantic, with `core.step.param`): a third-party
step uses the same ones, so plugins never import each other for them."""
from .pose import FIVE_DOF, INITIAL_HELP, MAX_ITER_HELP, PLANE_DOF, InitialPose, dof_for_surface, validate_dof
from .pupil import PupilCentreParams

__all__ = ["FIVE_DOF", "INITIAL_HELP", "MAX_ITER_HELP", "PLANE_DOF", "InitialPose", "dof_for_surface",
           "validate_dof", "PupilCentreParams"]

"""The one error of the resource model generation: a robot file, command declaration or tree skill declaration
that cannot be turned into a consistent model. Prints as ``FILE: KEY: PROBLEM (allowed: ...)``."""
from ..common.config_errors import ConfigError


class SkillModelError(ConfigError):
    """The robot's resource model cannot be built; nothing of it was handed out."""

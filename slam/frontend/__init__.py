"""Front end: register a scan's lines against a local line map before it enters the back-end."""

from slam.frontend.registration import (
    RegistrationConfig,
    RegistrationResult,
    register_lines,
)
from slam.lines.lineset import LineSet

__all__ = ["LineSet", "RegistrationConfig", "RegistrationResult", "register_lines"]

"""The laboratory, part 2: sampling techniques written by users, checked, rendered and compared.

- :mod:`~lightprobe.lab.techniques`: the contract (``sample(u, ctx) -> (wi, pdf)``, ``pdf(wi, ctx)``), the
  :class:`Context`, loading ``FILE.py:NAME`` and calling it safely, lightprobe's own techniques behind it;
- :mod:`~lightprobe.lab.jit_techniques`: techniques written as ``numba.njit`` functions of one sample (their
  :class:`JitContext`), called inside compiled loops;
- :mod:`~lightprobe.lab.check`: ``lightprobe check``, the project's verification applied to a user's technique;
- :mod:`~lightprobe.lab.render`: the laboratory's estimator, rendering a scene with user techniques (``compare``);
- :mod:`~lightprobe.lab.exercise`: the Krivanek exercise, packaged (``lightprobe exercise init / check``).
"""

from .check import CheckReport, check_technique
from .jit_techniques import EnvironmentRecord, JitContext
from .techniques import Context, GuardedTechnique, TechniqueError, direction_to_uv, load_technique, uv_to_direction

__all__ = [
    "CheckReport",
    "Context",
    "EnvironmentRecord",
    "GuardedTechnique",
    "JitContext",
    "TechniqueError",
    "check_technique",
    "direction_to_uv",
    "load_technique",
    "uv_to_direction",
]

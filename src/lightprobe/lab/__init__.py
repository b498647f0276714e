"""The laboratory, part 2: sampling techniques written by users, checked, rendered and compared.

- :mod:`~lightprobe.lab.techniques`: the contract (``sample(u, ctx) -> (wi, pdf)``, ``pdf(wi, ctx)``), the
  :class:`Context`, loading ``FILE.py:NAME`` and calling it safely, lightprobe's own techniques behind it;
- :mod:`~lightprobe.lab.check`: ``lightprobe check``, the project's verification applied to a user's technique;
- :mod:`~lightprobe.lab.render`: the laboratory's estimator, rendering a scene with user techniques (``compare``);
- :mod:`~lightprobe.lab.exercise`: the Krivanek exercise, packaged (``lightprobe exercise init / check``).
"""

from .check import CheckReport, check_technique
from .techniques import Context, GuardedTechnique, TechniqueError, direction_to_uv, load_technique, uv_to_direction

__all__ = [
    "CheckReport",
    "Context",
    "GuardedTechnique",
    "TechniqueError",
    "check_technique",
    "direction_to_uv",
    "load_technique",
    "uv_to_direction",
]

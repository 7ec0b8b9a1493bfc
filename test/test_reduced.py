"""Former home of the reduced-model tests: names re-exported for tests not yet moved."""

from toy_system import CONFIG, toy_samples, ZETA  # noqa: F401  SHIM

"""A Real FMU variable with a declared range, for the scene FMUs' parameters (pythonfmu's
Real writes a start value only). An importer holds a parameter to its ``min`` and ``max``
before the FMU runs (hycosim's loader refuses a value outside them, naming it); the FMU
itself would take any number. Packaged with the FMUs, as their scripts import it."""

from __future__ import annotations

from typing import Any

from pythonfmu import Real


class BoundedReal(Real):
    """A pythonfmu Real variable whose modelDescription.xml entry declares its ``min`` and ``max``."""

    def __init__(self, name: str, low: float, high: float, **kwargs: Any):
        super().__init__(name, **kwargs)
        self.low, self.high = low, high

    def to_xml(self) -> Any:
        element = super().to_xml()
        real = element.find("Real")
        real.set("min", f"{self.low:.16g}")
        real.set("max", f"{self.high:.16g}")
        return element

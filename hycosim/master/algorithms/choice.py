"""The master algorithm a project asks for, made once where the project is loaded.

``coSimulation.coupling`` chooses the scheme (Jacobi or Gauss-Seidel); ``iterate`` or
``stepControl`` wraps it; ``eventTolerance`` wraps that in event localisation. Or
``coSimulation.algorithm`` names a class of the user's (``module:Class`` or
``file.py:Class``, made with ``algorithmParameters``), which localisation wraps too.
"""

from __future__ import annotations

from pathlib import Path

from hycosim.core.config import LoadedProject
from hycosim.core.user_code import import_target
from hycosim.master.algorithms.gauss_seidel import GaussSeidel
from hycosim.master.algorithms.interface import Coupling, MasterAlgorithm
from hycosim.master.algorithms.iterated import Iterated
from hycosim.master.algorithms.jacobi import Jacobi
from hycosim.master.algorithms.localised import Localised
from hycosim.master.algorithms.step_controlled import StepControlled

_METHODS = ("plan", "step", "step_length", "startup_steps", "frames_only", "checkpoint", "restore")


class AlgorithmLoadError(ValueError):
    """The algorithm a project file names cannot be made; the message names it."""


def missing_methods(algorithm: object) -> list[str]:
    """The methods of :class:`MasterAlgorithm` that ``algorithm`` lacks."""
    return [m for m in _METHODS if not callable(getattr(algorithm, m, None))]


def user_algorithm(loaded: LoadedProject) -> MasterAlgorithm | None:
    """The project's ``coSimulation.algorithm``, made (None if it names none)."""
    cosim = loaded.project.coSimulation
    if cosim.algorithm is None:
        return None
    where = f"coSimulation.algorithm {cosim.algorithm!r}"
    base = loaded.path.parent if loaded.path is not None else Path.cwd()
    try:
        made = import_target(cosim.algorithm, base)(**cosim.algorithmParameters)
    except Exception as exc:  # the user's code may fail in any way; named, not a traceback
        raise AlgorithmLoadError(f"{where} cannot be made: {type(exc).__name__}: {exc}") from None
    if missing := missing_methods(made):
        raise AlgorithmLoadError(f"{where} is no master algorithm: it lacks {', '.join(missing)} "
                                 "(derive it from hycosim.master.algorithms.Algorithm)")
    return made


def project_algorithm(loaded: LoadedProject) -> MasterAlgorithm:
    """The algorithm that takes the project's steps (before the nodes say what they can)."""
    cosim = loaded.project.coSimulation
    coupling: Coupling = GaussSeidel() if cosim.coupling == "gauss-seidel" else Jacobi()
    algorithm = user_algorithm(loaded)
    if algorithm is None:
        if cosim.iterate is not None:
            algorithm = Iterated(cosim.iterate, coupling)
        elif cosim.stepControl is not None:
            algorithm = StepControlled(cosim.stepControl, cosim.stepSize, coupling)
        else:
            algorithm = coupling
    if cosim.eventTolerance is not None:
        algorithm = Localised(algorithm, coupling, cosim)
    return algorithm

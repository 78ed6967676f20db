"""Master algorithms: how a macro step is taken over the relay's barrier (interface.py), the
built-in ones each in a module of its own, and the choice of one for a project (choice.py)."""

from hycosim.master.algorithms.interface import (Algorithm, AlgorithmError, Barrier, Coupling, MasterAlgorithm,
                                                 StepRequest, StepTaken)
from hycosim.master.algorithms.jacobi import Jacobi
from hycosim.master.algorithms.gauss_seidel import GaussSeidel
from hycosim.master.algorithms.iterated import Iterated
from hycosim.master.algorithms.step_controlled import StepControlled
from hycosim.master.algorithms.localised import Localised

__all__ = ["Algorithm", "AlgorithmError", "Barrier", "Coupling", "GaussSeidel", "Iterated", "Jacobi", "Localised",
           "MasterAlgorithm", "StepControlled", "StepRequest", "StepTaken"]

"""hycosim: hybrid time/event co-simulation on the FMI standard, relayed over Eclipse Zenoh.

``hycosim.core`` holds what every part shares (the project file, frames, run files);
``hycosim.transport`` Zenoh sessions and the in-process bus; ``hycosim.master`` the relay and
its coordinator; ``hycosim.node`` the node interface and runtime; ``hycosim.fmi`` FMU import
(co-simulation, Model Exchange, SSP); ``hycosim.bridge`` FMU export and the gateway;
the paper's grasp demo is a package of its own beside them, which the framework never
imports; ``hycosim.dashboard`` the web dashboard;
``hycosim.cli`` the command line. ``hycosim.open(project)`` drives a run from Python
(:mod:`hycosim.api`).
"""


# The Python API (hycosim.api), imported when first asked for: ``import hycosim`` stays as light
# as every node process needs it.
_API = frozenset({"open", "Simulation", "Outcome", "SimulationError", "ProjectError", "PortError", "TimeError",
                  "ClosedError", "OverrideError", "ParameterError", "RunFailed"})
_OBSERVERS = frozenset({"Observer", "RecordedPoint", "LastValues", "TimeSeries"})
_ENSEMBLE = {"sweep": "hycosim.ensemble.sweep", "SweepError": "hycosim.ensemble.variants"}


def __getattr__(name: str):
    if name in _API:
        from hycosim import api

        return getattr(api, name)
    if name in _OBSERVERS:
        from hycosim.master import observers

        return getattr(observers, name)
    if name in _ENSEMBLE:
        import importlib

        return getattr(importlib.import_module(_ENSEMBLE[name]), name)
    # ``__version__`` is read from the installed metadata when first asked for, not at import:
    # importlib.metadata takes about 30 ms to import, and every node process imports hycosim.
    if name != "__version__":
        raise AttributeError(f"module 'hycosim' has no attribute {name!r}")
    from importlib.metadata import PackageNotFoundError, version

    try:
        # One version string: the package's metadata, written from pyproject.toml at install.
        found = version("hycosim")
    except PackageNotFoundError:  # the source tree on the import path, never installed
        found = "0+unknown"
    globals()["__version__"] = found
    return found

"""Finding the implementation a node entry names: a reference model, ``module:Class`` or
``file.py:Class``.

A model beside the project file loads without the user setting PYTHONPATH: ``module:Class``
is looked up on the import path with the project file's folder last on it (so that a module
there never shadows an installed one, nor the standard library; processes run ``python -P``),
and ``path/to/file.py:Class`` names a file relative to the project file.
"""

from __future__ import annotations

import importlib
import importlib.machinery
import importlib.util
import sys
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from hycosim.core.schema import CoSimulation
from hycosim.core.schema import Node as NodeSpec
from hycosim.core.extras import extra_providing, install_hint, missing_modules
from hycosim.core.hints import did_you_mean
from hycosim.core.user_code import import_module

from hycosim.node.interface import AsyncSource, Node, missing_state_methods

# The framework's own models. Other packages (the grasp demo among them) add theirs as entry points
# of the group MODEL_GROUP, ``name = "module:Class"``, read without importing them.
REFERENCE_MODELS = {
    "gain": "hycosim.node.reference.gain:Gain",
    "ramp": "hycosim.node.reference.ramp:Ramp",
    "pendulum": "hycosim.node.reference.pendulum:Pendulum",
    "bouncing_ball": "hycosim.node.reference.bouncing_ball:BouncingBall",
    "ramp_source": "hycosim.node.reference.ramp_source:RampSource",
}
MODEL_GROUP = "hycosim.models"
# FMU files a package knows how to build (the scene FMUs): an entry point named for the file,
# pointing at the command (a format string with {folder}) that builds it there.
FMU_BUILDER_GROUP = "hycosim.fmu_builders"


def _entry_points(group: str):
    # importlib.metadata costs ~30 ms to import: only a name that is no reference model pays it.
    from importlib.metadata import entry_points

    return entry_points(group=group)


def known_models() -> dict[str, str]:
    """Every model a node entry may name: the reference models and those installed packages
    register (entry points of ``hycosim.models``), each as ``module:Class``."""
    registered = {ep.name: f"{ep.module}:{ep.attr}" for ep in _entry_points(MODEL_GROUP)}
    return {**registered, **REFERENCE_MODELS}


def fmu_build_command(path: Path) -> str | None:
    """The command that builds the FMU file ``path`` where an installed package registered
    one for its name (``hycosim.fmu_builders``), else None."""
    for ep in _entry_points(FMU_BUILDER_GROUP):
        if ep.name == path.name:
            try:
                return str(ep.load()).format(folder=path.parent)
            except Exception:  # a damaged package's entry point: no hint rather than no message
                return None
    return None


class NodeLoadError(RuntimeError):
    """A node entry whose implementation cannot be found or made."""


def _fmu_path(spec: NodeSpec, project_dir: Path) -> Path:
    path = (project_dir / spec.fmu).resolve()
    if not path.is_file():
        command = fmu_build_command(path)
        hint = f"; build it with: {command}" if command else ""
        raise NodeLoadError(f"node {spec.nodeName!r}: FMU file {path} does not exist{hint}")
    if spec.asynchronous:
        raise NodeLoadError(f"node {spec.nodeName!r}: an FMU node steps; it cannot be asynchronous")
    return path


# The top-level packages hycosim installed before 0.2.0, when its modules moved under hycosim.
_OLD_TOP_LEVEL = ("clients", "core", "server", "fmu_bridge", "dashboard")
# Where 0.3.0 moved the packages a model could name.
_MOVED = {"hycosim.clients.": "hycosim.node (the reference models); name the grasp demo's models as registered: "
                               "rod, robot, reference_controller, camera, policy",
          "hycosim.fmu_bridge.": "hycosim.fmi or hycosim.bridge"}


def _missing_module_hint(missing: str | None, module_name: str) -> str:
    """What to do about a module that is not there: install the extra that brings it, or name
    the module as hycosim names it now."""
    extra = extra_providing(missing)
    if extra is not None:
        return f"; this model needs hycosim's [{extra}] extra: {install_hint(extra)}"
    if missing is not None and missing.partition(".")[0] in _OLD_TOP_LEVEL and module_name.startswith(missing):
        return f"; hycosim's modules are under hycosim. since 0.2.0: 'hycosim.{module_name}'"
    for old, new in _MOVED.items():
        if module_name.startswith(old):
            return f"; {old.rstrip('.')} moved in 0.3.0 to {new}"
    return ""


def model_class(spec: NodeSpec, project_dir: Path | None = None) -> type[Node] | type[AsyncSource]:
    """The class a Python node entry names, imported and checked against the entry: a Node
    for a stepping node, an AsyncSource for an asynchronous one, taking the parameters given.
    ``project_dir``: the project file's folder, where the user's own models may lie."""
    if not spec.model:
        raise NodeLoadError(f"node {spec.nodeName!r} names no 'model' to run; give a known model "
                            f"({', '.join(sorted(known_models()))}), 'module:Class' or 'file.py:Class'")
    target = REFERENCE_MODELS.get(spec.model) or (spec.model if ":" in spec.model else known_models().get(spec.model))
    module_name, _, class_name = (target or "").rpartition(":")
    if not module_name or not class_name:
        known = known_models()
        raise NodeLoadError(f"node {spec.nodeName!r}: model {spec.model!r} is neither a known model "
                            f"({', '.join(sorted(known))}) nor 'module:Class' or 'file.py:Class'"
                            f"{did_you_mean([spec.model], known)}")
    try:
        cls = getattr(import_module(module_name, project_dir or Path.cwd()), class_name)
    except Exception as exc:  # the user's module may fail to import in any way (SyntaxError, its own errors)
        detail = str(exc) if isinstance(exc, (ImportError, AttributeError)) else f"{type(exc).__name__}: {exc}"
        if isinstance(exc, ModuleNotFoundError):
            detail += _missing_module_hint(exc.name, module_name)
        raise NodeLoadError(f"node {spec.nodeName!r}: cannot load model {spec.model!r}: {detail}") from None
    kind = AsyncSource if spec.asynchronous else Node
    if not (isinstance(cls, type) and issubclass(cls, kind)):
        raise NodeLoadError(f"node {spec.nodeName!r} is asynchronous but {target} is not an AsyncSource"
                            if spec.asynchronous else f"node {spec.nodeName!r}: {target} is not a Node")
    _check_names(spec, "parameter", spec.parameters, cls.PARAMETERS)
    _check_names(spec, "input", spec.input_names(), cls.INPUTS)
    _check_names(spec, "output", spec.output_names(), cls.OUTPUTS)
    wrong = cls.parameter_problems(spec.parameters)
    if wrong:
        raise NodeLoadError(f"node {spec.nodeName!r}: model {spec.model!r}: {'; '.join(wrong)}")
    return cls


def locate_node(spec: NodeSpec, project_dir: Path) -> None:
    """Raise NodeLoadError for what fails however often it is tried, found without importing a
    model or loading an FMU: a model name that is neither known nor ``module:Class``, a module
    or ``.py`` file that is not there, a registered model whose extra is not installed, an FMU
    file that does not exist. A launcher calls it before it starts anything."""
    if spec.replay or not (spec.fmu or spec.model or spec.asynchronous):
        return
    if spec.fmu:
        _fmu_path(spec, project_dir)
        return
    if not spec.model:
        model_class(spec, project_dir)  # refused: an asynchronous node needs a model
    known = None if spec.model in REFERENCE_MODELS or ":" in spec.model else known_models()
    target = REFERENCE_MODELS.get(spec.model) or (spec.model if known is None else known.get(spec.model))
    module_name, _, class_name = (target or "").rpartition(":")
    if not module_name or not class_name:
        model_class(spec, project_dir)  # names the problem as a load does
    if module_name.endswith(".py"):
        if not (project_dir / module_name).is_file():
            raise NodeLoadError(f"node {spec.nodeName!r}: cannot load model {spec.model!r}: "
                                f"no file {(project_dir / module_name).resolve()}")
        return
    top = module_name.partition(".")[0]
    if top != "hycosim" and importlib.machinery.PathFinder.find_spec(top, [*sys.path, str(project_dir)]) is None \
            and top not in sys.builtin_module_names:
        raise NodeLoadError(f"node {spec.nodeName!r}: cannot load model {spec.model!r}: no module named {top!r}"
                            + _missing_module_hint(top, module_name))
    for extra in _extras_of(module_name):
        missing = missing_modules(extra)
        if missing:
            raise NodeLoadError(f"node {spec.nodeName!r}: model {spec.model!r} needs hycosim's [{extra}] extra "
                                f"({', '.join(missing)} not installed): {install_hint(extra)}")


def _extras_of(module_name: str) -> set[str]:
    # The extras a registered model declares (``name = "module:Class [extra]"``) hold for every
    # module of its package: the grasp configs name the demo's modules directly.
    needs: set[str] = set()
    for ep in _entry_points(MODEL_GROUP):
        package = ep.module.rpartition(".")[0]
        if ep.extras and package and (module_name == package or module_name.startswith(package + ".")):
            needs.update(ep.extras)
    return needs


def _check_names(spec: NodeSpec, kind: str, given: Iterable[str], declared: frozenset[str] | None) -> None:
    unknown = sorted(set(given) - declared) if declared is not None else []
    if unknown:
        raise NodeLoadError(f"node {spec.nodeName!r}: model {spec.model!r} has no {kind} "
                            f"{', '.join(map(repr, unknown))} (its {kind}s: {', '.join(sorted(declared)) or 'none'})"
                            + did_you_mean(unknown, declared))


def _player(spec: NodeSpec, project_dir: Path, cosim: CoSimulation) -> Node | AsyncSource:
    from hycosim.core.recordings import RecordingError

    from hycosim.node.replay import player

    try:
        return player(spec, project_dir, cosim)
    except RecordingError as exc:
        raise NodeLoadError(f"node {spec.nodeName!r}: {exc}") from None


def check_node(spec: NodeSpec, project_dir: Path, cosim: CoSimulation | None = None) -> None:
    """Raise NodeLoadError if the node's implementation could not be loaded as the entry says
    (without making it: no model is set up, no FMU binary loaded). A stepping node with neither
    model nor FMU is played by a bridge FMU in some tool: nothing to load here. A node that
    replays a recording (``cosim``: the project's, whose step size it must have) needs only that."""
    if spec.replay:
        _player(spec, project_dir, cosim or CoSimulation())  # reads the recording whole, as the node will
    elif spec.fmu:
        from hycosim.fmi.loader import FmuError, check_fmu

        try:
            check_fmu(_fmu_path(spec, project_dir), spec)
        except FmuError as exc:
            raise NodeLoadError(str(exc)) from None
    elif spec.model:
        model_class(spec, project_dir)
    elif spec.asynchronous:
        model_class(spec, project_dir)  # refused: an asynchronous node needs a model


def untunable(spec: NodeSpec, project_dir: Path, name: str) -> str | None:
    """Why parameter ``name`` of an FMU node cannot be set during a run (the FMU does not have it,
    or not as a tunable parameter), or None. Other nodes say what is tunable once set up (their
    HELLO), and the run refuses an action on anything else then. The node must load."""
    if not spec.fmu or spec.replay:
        return None
    from hycosim.fmi.loader import check_fmu

    md = check_fmu(_fmu_path(spec, project_dir), spec).md
    var = next((v for v in md.modelVariables if v.name == name), None)
    if var is None:
        return f"{Path(spec.fmu).name} has no variable {name!r}"
    if var.causality != "parameter" or var.variability != "tunable":
        return (f"{name!r} of {Path(spec.fmu).name} is {var.causality or 'local'}, {var.variability or 'continuous'}: "
                "only a parameter of variability 'tunable' can be set during a run")
    return None


_FMI1_NO_STATE = "its FMU is FMI 1.0, which has no state to get or set"


def why_no_checkpoint(spec: NodeSpec, project_dir: Path) -> str | None:
    """Why the node cannot take part in checkpoints (its state cannot outlive its process), or
    None if it can. The node must load (:func:`check_node`)."""
    if spec.asynchronous or spec.replay:
        return None  # a source is not rolled back (it goes on sampling); a player's state is its time
    if spec.fmu:
        from hycosim.fmi.loader import check_fmu

        mapping = check_fmu(_fmu_path(spec, project_dir), spec)
        if mapping.md.fmiVersion == "1.0":
            return _FMI1_NO_STATE
        cs = mapping.capabilities
        if not (getattr(cs, "canGetAndSetFMUstate", False) and getattr(cs, "canSerializeFMUstate", False)):
            return "its FMU does not declare canGetAndSetFMUstate and canSerializeFMUstate"
        return None
    if spec.model:
        cls = model_class(spec, project_dir)
        if cls.serialize_state is not Node.serialize_state:
            return None  # a model that serialises its own way
        # A model that overrides can_rollback answers only once set up: its HELLO tells the run.
        return missing_state_methods(cls)
    return "a bridge FMU cannot serialise the state of the tool it runs in"


def why_no_retake(spec: NodeSpec, project_dir: Path, variable: bool) -> str | None:
    """Why the node cannot take a step again after a rollback (shorter, with ``variable``), or
    None if it can or its bridge FMU's tool will say when it attaches. The node must load."""
    if spec.asynchronous or not (spec.fmu or spec.model or spec.replay):
        return None
    if spec.fmu:
        from hycosim.fmi.loader import check_fmu

        mapping = check_fmu(_fmu_path(spec, project_dir), spec)
        if mapping.md.fmiVersion == "1.0":
            return _FMI1_NO_STATE
        if not getattr(mapping.capabilities, "canGetAndSetFMUstate", False):
            return "its FMU does not declare canGetAndSetFMUstate"
        if variable and not mapping.variable_step:
            return "its FMU does not declare canHandleVariableCommunicationStepSize"
        return None
    if spec.replay:
        return None  # a player's state is its time
    cls = model_class(spec, project_dir)
    if (why := missing_state_methods(cls)) is not None:
        return why
    if variable:
        try:
            fixed = not cls().can_vary_step  # a model says so before its setup
        except Exception as exc:  # the user's constructor may fail in any way; the run will say how
            return f"its model {cls.__name__} cannot be made ({type(exc).__name__}: {exc})"
        if fixed:
            return f"its model {cls.__name__} takes steps of one length only (can_vary_step)"
    return None


def why_no_interpolation(spec: NodeSpec, project_dir: Path) -> str | None:
    """Why the node cannot make its inputs follow a polynomial over a step (iterative
    coupling's ``interpolate``), or None if it can. The node must load."""
    if spec.fmu:
        from hycosim.fmi.loader import MODEL_EXCHANGE, check_fmu

        mapping = check_fmu(_fmu_path(spec, project_dir), spec)
        if mapping.interface == MODEL_EXCHANGE:
            return "a Model Exchange FMU's node holds its inputs over a step"
        if mapping.md.fmiVersion.startswith("3"):
            return "FMI 3 co-simulation has no input derivatives"
        if not getattr(mapping.capabilities, "canInterpolateInputs", False):
            return "its FMU does not declare canInterpolateInputs"
        return None
    if spec.model and not spec.replay:
        cls = model_class(spec, project_dir)
        if cls.set_input_derivatives is Node.set_input_derivatives:
            return f"its model {cls.__name__} has no set_input_derivatives"
        return None
    return "a recording or a bridge FMU holds its inputs"


def fmu_mapping(spec: NodeSpec, project_dir: Path) -> Any:
    """The checked mapping of an FMU node's ports onto its FMU's variables (fmi.loader.FmuMapping)."""
    from hycosim.fmi.loader import check_fmu

    return check_fmu(_fmu_path(spec, project_dir), spec)


def feedthrough_of(spec: NodeSpec, project_dir: Path) -> dict[str, set[str]]:
    """Each output port of the node → the input ports it depends on directly (an FMU's model
    structure, a Python model's FEEDTHROUGH); empty for a node that does not say (a bridge FMU,
    a recording, an asynchronous source). The node must load."""
    if spec.fmu:
        from hycosim.fmi.loader import check_fmu

        return check_fmu(_fmu_path(spec, project_dir), spec).feedthrough()
    if spec.model and not spec.asynchronous:
        declared = model_class(spec, project_dir).FEEDTHROUGH or {}
        inputs = set(spec.input_names())
        return {out: set(ins) & inputs for out, ins in declared.items() if out in spec.output_names()}
    return {}


def load_node(spec: NodeSpec, project_dir: Path, cosim: CoSimulation | None = None) -> Node | AsyncSource:
    """Instantiate the implementation named by the node's ``model`` or ``fmu``, or the player
    of the recording its ``replay`` names."""
    if spec.replay:
        return _player(spec, project_dir, cosim or CoSimulation())
    if spec.fmu:
        from hycosim.node.fmu_node import FmuNode

        return FmuNode(spec, _fmu_path(spec, project_dir))
    return model_class(spec, project_dir)()

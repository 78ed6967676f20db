"""Finding the implementation a node entry names: a reference model or ``module:Class``."""

from __future__ import annotations

import importlib
from pathlib import Path

from fmu_bridge.config import Node as NodeSpec

from clients.node import AsyncSource, Node

REFERENCE_MODELS = {
    "gain": "clients.reference.gain:Gain",
    "ramp": "clients.reference.ramp:Ramp",
    "pendulum": "clients.reference.pendulum:Pendulum",
    "bouncing_ball": "clients.reference.bouncing_ball:BouncingBall",
    "ramp_source": "clients.reference.ramp_source:RampSource",
    "rod": "clients.rod.node:RodNode",
    "robot": "clients.robot.node:RobotNode",
    "reference_controller": "clients.robot.controller:ReferenceController",
    "camera": "clients.camera.node:CameraNode",
    "policy": "clients.policy.node:PolicyNode",
}


class NodeLoadError(RuntimeError):
    """A node entry whose implementation cannot be found or made."""


def load_node(spec: NodeSpec, project_dir: Path) -> Node | AsyncSource:
    """Instantiate the implementation named by the node's ``model`` or ``fmu``."""
    if spec.fmu:
        from clients.fmu_node import FmuNode

        path = (project_dir / spec.fmu).resolve()
        if not path.is_file():
            raise NodeLoadError(f"node {spec.nodeName!r}: FMU file {path} does not exist")
        if spec.asynchronous:
            raise NodeLoadError(f"node {spec.nodeName!r}: an FMU node steps; it cannot be asynchronous")
        return FmuNode(spec, path)
    if not spec.model:
        raise NodeLoadError(f"node {spec.nodeName!r} names no 'model' to run; give a reference model "
                            f"({', '.join(sorted(REFERENCE_MODELS))}) or 'module:Class'")
    target = REFERENCE_MODELS.get(spec.model, spec.model)
    module_name, _, class_name = target.partition(":")
    if not class_name:
        raise NodeLoadError(f"node {spec.nodeName!r}: model {spec.model!r} is neither a reference model "
                            f"({', '.join(sorted(REFERENCE_MODELS))}) nor 'module:Class'")
    try:
        cls = getattr(importlib.import_module(module_name), class_name)
    except (ImportError, AttributeError) as exc:
        raise NodeLoadError(f"node {spec.nodeName!r}: cannot load model {spec.model!r}: {exc}") from None
    impl = cls()
    if spec.asynchronous and not isinstance(impl, AsyncSource):
        raise NodeLoadError(f"node {spec.nodeName!r} is asynchronous but {target} is not an AsyncSource")
    if not spec.asynchronous and not isinstance(impl, Node):
        raise NodeLoadError(f"node {spec.nodeName!r}: {target} is not a Node")
    unknown = sorted(set(spec.parameters) - impl.PARAMETERS) if impl.PARAMETERS is not None else []
    if unknown:
        raise NodeLoadError(f"node {spec.nodeName!r}: model {spec.model!r} has no parameter "
                            f"{', '.join(map(repr, unknown))} (its parameters: {', '.join(sorted(impl.PARAMETERS))})")
    return impl

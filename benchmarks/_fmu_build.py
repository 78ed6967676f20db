"""Compile one C source into a native FMI 2.0 FMU for this machine (the benchmarks' own FMUs)."""

from __future__ import annotations

import platform
import shutil
import subprocess
import tempfile
import zipfile
from pathlib import Path


def native_fmu(source: Path, identifier: str, model_description: str, out: Path, flags: list[str]) -> Path:
    """Compile ``source`` with fmpy's FMI 2.0 headers and ``flags`` into
    ``binaries/linux64/<identifier>.so``, zip it with ``model_description`` as ``out``; return ``out``.
    RuntimeError naming what is missing or the compiler's words."""
    import fmpy

    if platform.system() != "Linux":
        raise RuntimeError(f"{source.name}: the benchmarks' FMUs are built for linux64 only")
    cc = shutil.which("gcc") or shutil.which("cc")
    if cc is None:
        raise RuntimeError(f"building {source.name} needs a C compiler (gcc or cc) on PATH")
    headers = Path(fmpy.__file__).parent / "c-code"
    out.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        binary = root / "binaries" / "linux64" / f"{identifier}.so"
        binary.parent.mkdir(parents=True)
        res = subprocess.run([cc, "-shared", "-fPIC", "-O2", "-std=c99", *flags, f"-I{headers}", "-o", str(binary),
                              str(source), "-lm"], capture_output=True, text=True)
        if res.returncode:
            raise RuntimeError(f"compiling {source.name} for {identifier} failed:\n{res.stderr.strip()}")
        (root / "modelDescription.xml").write_text(model_description)
        with zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED) as zf:
            for f in sorted(root.rglob("*")):
                if f.is_file():
                    zf.write(f, f.relative_to(root).as_posix())
    return out

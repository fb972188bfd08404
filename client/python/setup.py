"""Build hook: generates the gRPC stubs of ``fastrack.v1`` from ``../../proto`` while the package is built.

``grpc_tools.protoc`` (bundled protoc) writes ``fastrack/v1/{models,safety}_pb2.py`` and ``*_pb2_grpc.py``;
mypy-protobuf's plugins write their typed ``.pyi`` stubs beside them. A regular install (``pip install
./client/python``) writes nothing into the checkout, so it works from a read-only one: the stubs go into
the build's own folder, and the build folder and the package metadata into a temporary folder. Only an
editable install generates the stubs into ``src/`` (it imports from there); they are never committed
(``.gitignore``) and are rewritten whenever a ``.proto`` file is newer.
"""

from __future__ import annotations

import atexit
import shutil
import sys
import sysconfig
import tempfile
from pathlib import Path

from setuptools import setup
from setuptools.command.build_py import build_py

HERE = Path(__file__).resolve().parent
PROTO_ROOT = HERE.parent.parent / "proto"
PROTOS = ["fastrack/v1/models.proto", "fastrack/v1/safety.proto"]
SOURCE = HERE / "src"


def generated(out: Path) -> list[Path]:
    """The files protoc writes under ``out``."""
    return [
        out / "fastrack" / "v1" / f"{Path(p).stem}{suffix}"
        for p in PROTOS
        for suffix in ("_pb2.py", "_pb2.pyi", "_pb2_grpc.py", "_pb2_grpc.pyi")
    ]


def plugin(name: str) -> str:
    """Path of a protoc plugin script installed by mypy-protobuf (on PATH in pip's build environment)."""
    found = shutil.which(name) or shutil.which(name, path=sysconfig.get_path("scripts"))
    if found is None:
        found = shutil.which(name, path=str(Path(sys.executable).parent))
    if found is None:
        raise RuntimeError(f"{name} not found: install mypy-protobuf (a build requirement of this package)")
    return found


def generate(out: Path) -> None:
    """Runs protoc into ``out`` unless every generated file there is newer than every .proto file."""
    sources = [PROTO_ROOT / p for p in PROTOS]
    if not all(s.is_file() for s in sources):
        if all(g.is_file() for g in generated(out)):
            return  # built from a copy without proto/ (e.g. an sdist) whose stubs were generated already
        raise RuntimeError(f"the .proto files are missing: expected {', '.join(map(str, sources))}")
    newest = max(s.stat().st_mtime for s in sources + [Path(__file__)])
    if all(g.is_file() and g.stat().st_mtime >= newest for g in generated(out)):
        return
    from grpc_tools import protoc  # build requirement, imported only when generating

    well_known = Path(protoc.__file__).parent / "_proto"
    args = [
        "grpc_tools.protoc",
        f"-I{PROTO_ROOT}",
        f"-I{well_known}",
        f"--python_out={out}",
        f"--grpc_python_out={out}",
        f"--plugin=protoc-gen-mypy={plugin('protoc-gen-mypy')}",
        f"--plugin=protoc-gen-mypy_grpc={plugin('protoc-gen-mypy_grpc')}",
        f"--mypy_out={out}",
        f"--mypy_grpc_out={out}",
        *PROTOS,
    ]
    if protoc.main(args) != 0:
        raise RuntimeError("protoc failed to generate the fastrack.v1 stubs (see its message above)")


class BuildWithStubs(build_py):
    """``build_py`` that generates the stubs: into the build folder, or into ``src/`` for an editable install."""

    def run(self) -> None:
        if self.editable_mode:
            generate(SOURCE)
            self.__dict__.pop("data_files", None)  # recomputed lazily, now that the .pyi files exist
            super().run()
        else:
            super().run()
            generate(Path(self.build_lib))


# The build folder and the egg-info metadata go into a temporary folder, not into the checkout.
SCRATCH = Path(tempfile.mkdtemp(prefix="fastrack-client-build-"))
atexit.register(shutil.rmtree, SCRATCH, ignore_errors=True)

setup(
    cmdclass={"build_py": BuildWithStubs},
    options={"build": {"build_base": str(SCRATCH / "build")}, "egg_info": {"egg_base": str(SCRATCH)}},
)

"""Build hook: generates the gRPC stubs from the repository's proto.

The wire contract lives once, in <repo>/proto/outcore/v1/scene_query.proto.
build_py runs grpcio-tools' protoc on it and writes scene_query_pb2{,_grpc}.py
into the built package (or into src/ for editable installs). The proto is
looked up, in order, in $OUTCORE_PROTO_DIR, <this dir>/../../proto (building
from the repository, which pip does in place) and <this dir>/proto (an sdist,
into which the sdist command below copies it).
"""

import os
import pathlib
import shutil

from setuptools import setup
from setuptools.command.build_py import build_py
from setuptools.command.sdist import sdist

HERE = pathlib.Path(__file__).resolve().parent
PROTO = pathlib.Path("outcore/v1/scene_query.proto")


def _proto_root() -> pathlib.Path:
    candidates = []
    if os.environ.get("OUTCORE_PROTO_DIR"):
        candidates.append(pathlib.Path(os.environ["OUTCORE_PROTO_DIR"]))
    candidates += [HERE.parent.parent / "proto", HERE / "proto"]
    for root in candidates:
        if (root / PROTO).is_file():
            return root
    raise RuntimeError(
        f"cannot find {PROTO} under any of: {', '.join(str(c) for c in candidates)} "
        "(build from the Outcore repository, or set OUTCORE_PROTO_DIR)"
    )


def _generate_stubs(out_dir: pathlib.Path) -> None:
    import grpc_tools
    from grpc_tools import protoc

    root = _proto_root()
    well_known = pathlib.Path(grpc_tools.__file__).parent / "_proto"
    args = [
        "grpc_tools.protoc",
        f"-I{root}",
        f"-I{well_known}",
        f"--python_out={out_dir}",
        f"--pyi_out={out_dir}",
        f"--grpc_python_out={out_dir}",
        str(root / PROTO),
    ]
    if protoc.main(args) != 0:
        raise RuntimeError(f"protoc failed on {root / PROTO}")


class BuildPyWithStubs(build_py):
    def run(self):
        super().run()
        out = HERE / "src" if getattr(self, "editable_mode", False) else pathlib.Path(self.build_lib)
        _generate_stubs(out)


class SdistWithProto(sdist):
    def make_release_tree(self, base_dir, files):
        super().make_release_tree(base_dir, files)
        target = pathlib.Path(base_dir) / "proto" / PROTO
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(_proto_root() / PROTO, target)


setup(cmdclass={"build_py": BuildPyWithStubs, "sdist": SdistWithProto})

"""The build step of the carvemap package: the job API's gRPC stubs (carvemap/v1/jobs_pb2.py,
jobs_pb2_grpc.py) generated from the repository's proto/carvemap/v1/jobs.proto with
grpc_tools.protoc into the build, so that nothing generated is checked in and an install needs
no network. The metadata is in pyproject.toml."""
import os

from setuptools import setup
from setuptools.command.build_py import build_py

HERE = os.path.dirname(os.path.abspath(__file__))
PROTO = os.path.join("carvemap", "v1", "jobs.proto")


def proto_root():
    """The proto root: $CARVEMAP_PROTO_DIR, the repository's ../proto, or ./proto (a copy)."""
    candidates = [os.environ.get("CARVEMAP_PROTO_DIR"), os.path.join(HERE, "..", "proto"),
                  os.path.join(HERE, "proto")]
    for root in candidates:
        if root and os.path.isfile(os.path.join(root, PROTO)):
            return os.path.abspath(root)
    raise SystemExit(f"carvemap: {PROTO} not found under ../proto or ./proto (build from the "
                     "repository's python/ folder, or set CARVEMAP_PROTO_DIR)")


class BuildPyWithStubs(build_py):
    def run(self):
        super().run()
        try:
            from grpc_tools import protoc
        except ImportError as e:
            raise SystemExit(f"carvemap: {e}: the build generates the gRPC stubs with "
                             "grpc_tools (Debian: python3-grpc-tools; pip: grpcio-tools)")
        root = proto_root()
        out = os.path.abspath(self.build_lib)
        os.makedirs(os.path.join(out, "carvemap", "v1"), exist_ok=True)
        rc = protoc.main(["grpc_tools.protoc", f"-I{root}", f"--python_out={out}",
                          f"--grpc_python_out={out}", os.path.join(root, PROTO)])
        if rc != 0:
            raise SystemExit(f"carvemap: grpc_tools.protoc failed ({rc}) on {root}/{PROTO}")

    def get_outputs(self, include_bytecode=1):
        generated = [os.path.join(self.build_lib, "carvemap", "v1", name)
                     for name in ("jobs_pb2.py", "jobs_pb2_grpc.py")]
        return super().get_outputs(include_bytecode) + generated


setup(cmdclass={"build_py": BuildPyWithStubs})

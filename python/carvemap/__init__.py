"""carvemap from Python: write and read scan.h5 (carvemap.scan), run jobs on a carvemap
server (carvemap.client) and load a job's outputs (carvemap.outputs). docs/DESIGN.md §3 and §7
are the formats, docs/RPC.md the job API."""
__version__ = "0.1.0"

_LAZY = {
    "ScanWriter": "scan", "ScanReader": "scan", "read_scan": "scan", "write_scan": "scan",
    "JobClient": "client", "JobError": "client",
    "load_outputs": "outputs",
}
__all__ = sorted(_LAZY)


def __getattr__(name):
    # Each module is imported when first used: writing a scan needs neither grpc nor stubs.
    if name in _LAZY:
        import importlib
        return getattr(importlib.import_module(f"{__name__}.{_LAZY[name]}"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")

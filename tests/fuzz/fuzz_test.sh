#!/usr/bin/env bash
# The fuzz targets in the test suite (tests/CMakeLists.txt) and by hand (README.md here).
#   fuzz_test.sh build BUILD_DIR             configure tests/fuzz with clang-14 into BUILD_DIR, build
#   fuzz_test.sh run BUILD_DIR TARGET SECONDS [libFuzzer flags...]
#       runs BUILD_DIR/TARGET_fuzzer for SECONDS on the seeds in corpus/TARGET (read-only; new
#       inputs go to BUILD_DIR/work/TARGET, started afresh each run), crashes to
#       BUILD_DIR/artifacts/TARGET/. Fails, naming the input and how to reproduce it, when
#       the target crashes, leaks, runs out of memory (2.5 GB) or takes over 10 s on one input.
#   fuzz_test.sh coverage COV_DIR BUILD_DIR TARGET SOURCE...
#       builds the targets with source-based coverage into COV_DIR, runs TARGET once over its
#       seeds and BUILD_DIR/work/TARGET (the corpus the last run grew), and prints llvm-cov's
#       line and branch coverage of each SOURCE (paths in the repository).
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"

case "${1:-}" in
  build)
    build="$2"
    cxx="${CARVEMAP_FUZZ_CXX:-clang++-14}"
    cc="${CARVEMAP_FUZZ_CC:-clang-14}"
    command -v "$cxx" >/dev/null || {
      echo "fuzz: $cxx not found (scripts/install-deps.sh installs clang-14 and libclang-rt-14-dev)" >&2
      exit 1
    }
    cmake -S "$here" -B "$build" -G Ninja -DCMAKE_CXX_COMPILER="$cxx" -DCMAKE_C_COMPILER="$cc" \
      > "$build.configure.log" 2>&1 || { cat "$build.configure.log" >&2; exit 1; }
    cmake --build "$build" -j "${CARVEMAP_FUZZ_BUILD_JOBS:-$(nproc)}"
    ;;
  run)
    build="$2" target="$3" seconds="$4"
    shift 4
    work="$build/work/$target" artifacts="$build/artifacts/$target"
    case "$target" in  # the format's words help mutations reach past the header parsers
      ply_import|ply_mesh) set -- -dict="$here/dict/ply.dict" "$@" ;;
      scan_reader*) set -- -dict="$here/dict/scan.dict" "$@" ;;
      tile_reader*) set -- -dict="$here/dict/tile.dict" "$@" ;;
      tum_import|png) set -- -dict="$here/dict/tum.dict" "$@" ;;
      carmen_import) set -- -dict="$here/dict/carmen.dict" "$@" ;;
      e57_import) set -- -dict="$here/dict/e57.dict" "$@" ;;
    esac
    rm -rf "$work"
    mkdir -p "$work" "$artifacts"
    status=0
    # libFuzzer's -timeout is wall time: on a loaded machine a niced input that runs in 0.15 s
    # waited > 10 s for a core and was reported as a hang, so 60 s (any real hang still shows).
    "$build/${target}_fuzzer" -max_total_time="$seconds" -timeout=60 -rss_limit_mb=2560 \
      -print_final_stats=1 -artifact_prefix="$artifacts/" "$@" "$work" "$here/corpus/$target" \
      2>&1 | grep -v -E '^#[0-9]+.*(NEW|REDUCE|pulse)|NEW_FUNC' || status=${PIPESTATUS[0]}
    # A target's scratch dir (fuzz_util.h ScratchDir) is removed at a normal exit only; a
    # timeout, crash or fork-mode child leaves it on tmpfs (once a 13 GB scan.h5 in /dev/shm).
    # Remove those of processes that are gone (other targets may be running beside this one).
    for d in /dev/shm/carvemap_fuzz_* "${TMPDIR:-/tmp}"/carvemap_fuzz_*; do
      [ -d "$d" ] || continue
      kill -0 "${d##*_}" 2>/dev/null || rm -rf "$d"
    done
    if [ "$status" -ne 0 ]; then
      echo "fuzz: $target failed (exit $status). Inputs that failed:" >&2
      ls -1 "$artifacts" >&2
      echo "Reproduce: $build/${target}_fuzzer $artifacts/<input>" >&2
      exit 1
    fi
    ;;
  coverage)
    cov="$2" build="$3" target="$4"
    shift 4
    root="$(cd "$here/../.." && pwd)"
    cmake -S "$here" -B "$cov" -G Ninja -DCMAKE_CXX_COMPILER="${CARVEMAP_FUZZ_CXX:-clang++-14}" \
      -DCMAKE_C_COMPILER="${CARVEMAP_FUZZ_CC:-clang-14}" -DCARVEMAP_FUZZ_COVERAGE=ON >/dev/null
    cmake --build "$cov" --target "${target}_fuzzer" >/dev/null
    rm -f "$cov/$target.profraw"
    LLVM_PROFILE_FILE="$cov/$target.profraw" ASAN_OPTIONS=detect_leaks=0 \
      "$cov/${target}_fuzzer" -runs=0 "$build/work/$target" "$here/corpus/$target" >/dev/null 2>&1
    llvm-profdata-14 merge -sparse "$cov/$target.profraw" -o "$cov/$target.profdata"
    llvm-cov-14 report "$cov/${target}_fuzzer" -instr-profile="$cov/$target.profdata" \
      "${@/#/$root/}"
    ;;
  *)
    echo "usage: fuzz_test.sh build BUILD_DIR | run BUILD_DIR TARGET SECONDS [flags...]" >&2
    echo "       | coverage COV_DIR BUILD_DIR TARGET SOURCE..." >&2
    exit 2
    ;;
esac

#!/usr/bin/env bash
# Installs what carvemap needs to build and test on Debian 12, from Debian's packages only.
# Idempotent: packages already present are skipped, and nothing runs when all are there.
set -euo pipefail

PACKAGES=(
  build-essential cmake ninja-build pkg-config
  ccache  # cmake/ccache.cmake: a rebuild, or a fresh clone's build, reuses what was compiled
  liboctomap-dev octomap-tools libeigen3-dev libcgal-dev
  libspectra-dev  # services/floorplan/eigencrust/eigencrust.cc: generalized sparse eigensolver (§3.2.2)
  libgrpc++-dev protobuf-compiler-grpc libprotobuf-dev protobuf-compiler
  libhdf5-dev hdf5-tools libspdlog-dev libsqlite3-dev
  libgtest-dev libgmock-dev libbenchmark-dev
  libcli11-dev nlohmann-json3-dev libpng-dev libembree-dev libtbb-dev libssl-dev
  zlib1g-dev  # storage/import/carmen_import.cc: gzipped CARMEN logs
  libbz2-dev  # storage/import/decompress.cc: bz2 chunks of ROS 1 bags
  libzstd-dev liblz4-dev  # storage/import/decompress.cc: lz4 and zstd chunks of ROS bags and MCAP
  libpugixml-dev  # storage/import/e57_reader.cc: the XML section of E57 files
  libdxflib-dev  # services/floorplan/export/floorplan_dxf.cc: floorplan.dxf
  python3-ezdxf  # tests/tools/check_outputs.py: an independent reader of floorplan.dxf
  python3-pil  # tests/tools/check_outputs.py: an independent reader of occupancy.pgm
  libtinygltf-dev  # storage/glb_writer_test.cc: an independent reader of mesh/model.glb
  libifcplusplus-dev  # tests/tools/ifcpp_check.cc: an independent reader of building.ifc
  libjs-three libjs-leaflet  # services/report: the report's 3D view and floor plans
  libcivetweb-dev  # `carvemap serve`
  chromium  # tests/tools/report_test.py: the report in a real browser, headless
  # tests/tools/make_rosbag.py: ROS 1 bags written by ROS's own Python library
  python3-rosbag python3-roslz4 python3-sensor-msgs python3-tf2-msgs python3-geometry-msgs
  libgeographiclib-dev  # services/geomag/: the World Magnetic Model's declination (§2.3)
  openssl  # the CLI: tests/tools/make_test_pki.sh (TLS tests)
  prometheus-cpp-dev libcurl4-openssl-dev  # the coordinator's /metrics; `watch --metrics`
  python3 python3-h5py python3-numpy
  yamllint python3-yaml kubernetes-client
  python3-grpcio python3-grpc-tools  # tests/tools: an independent client of the job API
  # python/: pip builds the package offline (--no-build-isolation), into a venv over these
  python3-pip python3-setuptools python3-wheel python3-venv
  python3-pytest  # python/tests: the Python package's tests (ctest python_package)
  iproute2  # tests/tools/fault_test.py, deploy/local/netns.sh: ip netns, veth links
  time  # /usr/bin/time: CPU seconds in tests/bench/*.sh (e2e_floorplan_3d_freiburg101 runs one)
  strace  # tests/tools/durability_trace.py: the order of fsyncs and renames in a real job
  prometheus  # tests/tools/prometheus_test.py: a real server scrapes every carvemap service
  clang-14 libclang-rt-14-dev  # tests/fuzz: libFuzzer and the ASan/UBSan runtimes
)

missing=()
for p in "${PACKAGES[@]}"; do
  # deploy/ tests need a kubectl; another vendor's package may provide it already (and Debian's
  # would then conflict with it on /usr/bin/kubectl).
  if [ "$p" = kubernetes-client ] && command -v kubectl >/dev/null; then continue; fi
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
    missing+=("$p")
  fi
done

if [ ${#missing[@]} -eq 0 ]; then
  echo "install-deps: all ${#PACKAGES[@]} packages present"
  exit 0
fi

SUDO=""
if [ "$(id -u)" -ne 0 ]; then
  command -v sudo >/dev/null || { echo "install-deps: need root or sudo to install: ${missing[*]}" >&2; exit 1; }
  SUDO="sudo"
fi
echo "install-deps: installing ${missing[*]}"
$SUDO apt-get update -qq
DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}"

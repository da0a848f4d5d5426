#!/usr/bin/env bash
# Bad input through the CLI: each case must fail with a non-zero exit and a message that names
# the file and says what is wrong. Usage: bad_input_test.sh CARVEMAP GOOD_SCAN.h5 WORKDIR
set -u
carvemap="$1"; good="$2"; work="$3"
mkdir -p "$work"
failures=0

expect_error() {  # expect_error NAME PATTERN FILE
  local name="$1" pattern="$2" file="$3" out rc
  out="$("$carvemap" validate "$file" 2>&1)"; rc=$?
  if [ "$rc" -eq 0 ]; then
    echo "FAIL $name: exit 0 for bad input"; failures=$((failures + 1)); return
  fi
  if ! grep -q -- "$file" <<<"$out"; then
    echo "FAIL $name: message does not name the file: $out"; failures=$((failures + 1)); return
  fi
  if ! grep -qiE -- "$pattern" <<<"$out"; then
    echo "FAIL $name: message lacks /$pattern/: $out"; failures=$((failures + 1)); return
  fi
  echo "ok   $name: $out"
}

size=$(stat -c %s "$good")
head -c $((size / 2)) "$good" > "$work/truncated.h5"
expect_error truncated "truncat|corrupt" "$work/truncated.h5"
printf 'this is not hdf5\n' > "$work/garbage.h5"
expect_error not_hdf5 "not an HDF5|not HDF5|corrupt" "$work/garbage.h5"
expect_error missing "no such file|not found|does not exist|cannot open" "$work/missing.h5"
: > "$work/empty.h5"
expect_error empty "truncat|corrupt|empty|not an HDF5|not HDF5" "$work/empty.h5"

# The validator accepts the good file.
if ! "$carvemap" validate "$good" > /dev/null 2>&1; then
  echo "FAIL good file rejected"; failures=$((failures + 1))
fi
echo "$((4 + 1 - failures)) passed, $failures failed"
[ "$failures" -eq 0 ]

#!/usr/bin/env bash
# yamllint --strict (warnings fail too) on every YAML file under deploy/, with deploy/.yamllint.
# Fails, never skips, when yamllint is missing.
set -euo pipefail
deploy="$(cd "$(dirname "$0")/.." && pwd)"
YAMLLINT=/usr/bin/yamllint
[ -x "$YAMLLINT" ] || YAMLLINT=$(command -v yamllint || true)
if [ -z "$YAMLLINT" ]; then
  echo "FAIL: yamllint not found: run scripts/install-deps.sh (Debian package yamllint)" >&2
  exit 1
fi
mapfile -t files < <(find "$deploy" -name '*.yaml' -o -name '*.yml' -o -name .yamllint | sort)
if [ ${#files[@]} -lt 2 ]; then
  echo "FAIL: no YAML files found under $deploy" >&2
  exit 1
fi
"$YAMLLINT" --strict -c "$deploy/.yamllint" "${files[@]}"
echo "yamllint: ${#files[@]} files clean"

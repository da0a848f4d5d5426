#!/usr/bin/env bash
# A throw-away PKI for TLS tests (tests/security_test.cc), made with the openssl CLI at test
# time so no key is ever checked in. Usage: make_test_pki.sh DIR
#   ca.crt ca.key          test CA
#   server.crt server.key  signed by it, for localhost, 127.0.0.1 and carvemap-coordinator
#   worker.crt worker.key  client certificate signed by it (mutual TLS of a worker)
#   other-ca.crt           another CA (trusting it must fail)
#   rogue.crt rogue.key    a client certificate signed by the other CA
set -euo pipefail
DIR=$1
mkdir -p "$DIR"
cd "$DIR"
key() { openssl genpkey -algorithm EC -pkeyopt ec_paramgen_curve:prime256v1 -out "$1" 2>/dev/null; }
ca() {  # ca NAME CN
  key "$1.key"
  openssl req -x509 -new -key "$1.key" -sha256 -days 2 -subj "/CN=$2" \
      -addext basicConstraints=critical,CA:TRUE -addext keyUsage=critical,keyCertSign,cRLSign \
      -out "$1.crt"
}
leaf() {  # leaf NAME CA CN EXTENSIONS
  key "$1.key"
  openssl req -new -key "$1.key" -subj "/CN=$3" -out "$1.csr"
  printf '%s\n' "$4" > "$1.ext"
  openssl x509 -req -in "$1.csr" -CA "$2.crt" -CAkey "$2.key" -CAcreateserial -sha256 -days 2 \
      -extfile "$1.ext" -out "$1.crt" 2>/dev/null
  rm -f "$1.csr" "$1.ext"
}
ca ca "carvemap test CA"
ca other-ca "some other CA"
leaf server ca carvemap-coordinator \
  "subjectAltName=DNS:localhost,IP:127.0.0.1,DNS:carvemap-coordinator
extendedKeyUsage=serverAuth"
leaf worker ca carvemap-worker "extendedKeyUsage=clientAuth"
leaf rogue other-ca carvemap-worker "extendedKeyUsage=clientAuth"
chmod 600 ./*.key
